"""The scene's geometry as one flat triangle mesh, with per-triangle data.

All shapes of a scene are concatenated into a single mesh; each triangle
records the material and the shape it came from.  The arrays estimators need
per hit (first vertex, edges, unit geometric normal, area) are precomputed
once in structure-of-arrays form.
"""
from __future__ import annotations

import numpy as np

from .. import _native
from ..vecmath import gamma

__all__ = ["TriangleMesh", "triangle_cross", "HIT_POINT_ROUNDINGS"]

# A hit point p = p0 + b1 e1 + b2 e2 is reconstructed in float32 from the barycentrics Embree reports
# (pbrt-v4, sec. 6.8.5): the barycentrics only move p within the triangle's plane, and the arithmetic
# -- p0, e1, e2 rounded to float32, two products and two sums, plus the rounding of the vertices Embree
# traces -- leaves p within gamma(7) (|p0| + |e1| + |e2|) of that plane, per coordinate.  Along the unit
# normal n that is epsilon = gamma(7) sum_c |n_c| (|p0_c| + |e1_c| + |e2_c|), the ray offset of the
# triangle (see :func:`pathspace.vecmath.offset_origin`).  It bounds Embree's own error in the sign of a
# leaving ray's distance to the plane too (its terms are (v_i - origin) . n, each within the same sums).
# Coordinates are relative to the scene's render origin (see :class:`pathspace.scene.Scene`), so the
# bound is small wherever the scene sits in the world.
HIT_POINT_ROUNDINGS = 7
# The least offset, relative to the triangle's coordinates (far below any rounding, far above underflow).
EXACT_PLANE_OFFSET = 2.0 ** -40


def triangle_cross(vertices: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """(p1 - p0) x (p2 - p0) of each triangle as an (F, 3) float64 array.

    Its direction is the geometric normal (counter-clockwise winding, right-hand
    rule) and its length twice the triangle's area.
    """
    p = vertices[indices]
    return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])


class TriangleMesh:
    """Triangles of a scene: vertices, indices, and per-triangle material and shape ids.

    Attributes
    ----------
    vertices : (V, 3) float64
    indices : (F, 3) uint32
    material : (F,) int32, index into the scene's material table
    shape : (F,) int32, index into the scene's shape list
    table : (13, F) float32, rows p0 (first vertex), e1 = p1 - p0, e2 = p2 - p0,
        the unit geometric normal (right-hand rule) and the ray offset epsilon, a bound on the error of
        reconstructed hit points along the normal (see HIT_POINT_ROUNDINGS)
    normal : (3, F) float32, a view of the normal rows
    area : (F,) float64
    """

    def __init__(self, vertices: np.ndarray, indices: np.ndarray, material: np.ndarray, shape: np.ndarray) -> None:
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.indices = np.ascontiguousarray(indices, dtype=np.uint32)
        self.material = np.ascontiguousarray(material, dtype=np.int32)
        self.shape = np.ascontiguousarray(shape, dtype=np.int32)
        p = self.vertices[self.indices]
        e1 = p[:, 1] - p[:, 0]
        e2 = p[:, 2] - p[:, 0]
        n = triangle_cross(self.vertices, self.indices)
        double_area = np.linalg.norm(n, axis=1)
        self.area = 0.5 * double_area
        # Rows 0-2: p0, 3-5: e1 = p1 - p0, 6-8: e2 = p2 - p0, 9-11: unit normal, 12: ray
        # offset; one gather of this table gives everything a hit needs.
        table = np.concatenate([p[:, 0], e1, e2, n / double_area[:, None]], axis=1).astype(np.float32).T
        stored = table.astype(np.float64)
        spread = np.abs(stored[0:3]) + np.abs(stored[3:6]) + np.abs(stored[6:9])
        epsilon = gamma(HIT_POINT_ROUNDINGS) * np.sum(np.abs(stored[9:12]) * spread, axis=0)
        # A plane through the render origin along an axis is exact (a zero bound): stand off it a little
        # anyway, or Embree would find the surface again at t = 0.
        epsilon = np.maximum(epsilon, EXACT_PLANE_OFFSET * spread.max(axis=0))
        self.table = np.ascontiguousarray(np.vstack([table, epsilon[None].astype(np.float32)]))
        self.normal = self.table[9:12]

    @property
    def triangle_count(self) -> int:
        """Number of triangles."""
        return int(self.indices.shape[0])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounding box (lower, upper corners)."""
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def hit_geometry(self, prim: np.ndarray, b1: np.ndarray, b2: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Points (1-b1-b2) p0 + b1 p1 + b2 p2 and unit geometric normals, (3, N) float32, on triangles
        ``prim`` (integers; IndexError for any that is not a triangle), and their ray offsets epsilon (N,)
        float32; barycentrics ``b1``, ``b2`` in float32 (as Embree reports them; others are rounded to it).
        Computed in C in one pass (``ext/geometry.c``): p0 + b1 e1 + b2 e2 from the table's rows, in float32."""
        prim = np.asarray(prim)
        if prim.dtype not in (np.int32, np.int64):
            prim = prim.astype(np.int64, casting="safe")
        b1, b2 = (np.ascontiguousarray(b, dtype=np.float32) for b in (b1, b2))
        return _native.hit_geometry(self.table, np.ascontiguousarray(prim), b1, b2)
