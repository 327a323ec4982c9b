"""Hit geometry in C (``TriangleMesh.hit_geometry``, ``ext/geometry.c``) against its NumPy reference: the same
float32 points, normals and ray offsets, bit for bit, on triangles of every size and distance from the origin,
at barycentrics on the edges and corners too; bad triangle indices are refused."""
from __future__ import annotations

import numpy as np
import pytest

from pathspace.scene.mesh import TriangleMesh


def reference(mesh: TriangleMesh, prim, b1, b2):
    """The NumPy expression the C kernel replaces: one gather of the table, p0 + e1 b1 + e2 b2 in float32."""
    rows = np.take(mesh.table, prim, axis=1)
    return rows[0:3] + rows[3:6] * b1 + rows[6:9] * b2, rows[9:12], rows[12]


@pytest.mark.parametrize("scale,distance", [(1e-4, 0.0), (1.0, 0.0), (1e3, 1e5), (1.0, 1e4)])
def test_hit_geometry_is_the_numpy_reference(scale, distance):
    rng = np.random.default_rng(3)
    count = 5000
    vertices = rng.normal(size=(3 * count, 3)) * scale + rng.normal(size=3) * distance
    mesh = TriangleMesh(vertices, np.arange(3 * count).reshape(-1, 3), np.zeros(count), np.zeros(count))
    n = 100_000
    prim = rng.integers(0, count, n).astype(np.int32 if scale < 1e3 else np.int64)   # Embree's int32, or int64
    prim[:2] = 0, count - 1
    u = rng.uniform(size=(2, n)).astype(np.float32)
    b1, b2 = np.where(u.sum(0) > 1, 1 - u, u)
    corners = rng.integers(0, 3, 1000)          # vertices and edges: barycentrics 0 and 1
    b1[:1000], b2[:1000] = (corners == 1).astype(np.float32), (corners == 2).astype(np.float32)
    found, expected = mesh.hit_geometry(prim, b1, b2), reference(mesh, prim, b1, b2)
    for name, got, want in zip(("p", "normal", "eps"), found, expected):
        assert got.dtype == np.float32 and got.shape == want.shape
        np.testing.assert_array_equal(got, want, err_msg=name)


def test_bad_triangle_indices_are_refused():
    mesh = TriangleMesh(np.eye(3), np.array([[0, 1, 2]]), np.zeros(1), np.zeros(1))
    with pytest.raises(IndexError, match=r"prim\[1\] = 1 is not a triangle"):
        mesh.hit_geometry(np.array([0, 1]), np.zeros(2), np.zeros(2))
    with pytest.raises(IndexError, match="not a triangle"):
        mesh.hit_geometry(np.array([2 ** 32]), np.zeros(1), np.zeros(1))   # no silent wrap-around
    with pytest.raises(TypeError):
        mesh.hit_geometry(np.array([0.0]), np.zeros(1), np.zeros(1))
    with pytest.raises(ValueError, match="same length"):
        mesh.hit_geometry(np.array([0, 0]), np.zeros(3), np.zeros(2))
