"""Ray offsets from floating-point error bounds (pbrt-v4, sec. 6.8): rays leaving a surface never hit it
again, shadow rays between two mutually visible surface points are never blocked by the surfaces they
join, and surfaces a few float32 roundings apart are still told apart -- at any orientation, any
triangle size, any distance from the render origin and any angle, grazing included."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import pathspace as ps
from pathspace import Accel, _native
from pathspace.estimators.visibility import segment_blocked
from pathspace.scene.mesh import TriangleMesh
from pathspace.vecmath import RAY_TMIN, dot, offset_origin, shadow_ray
from conftest import scene_dict


def random_rotations(rng, n):
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], 1)


def triangles_in_cells(rng, count, distance, size):
    """``count`` random triangles (random shape and orientation, edges ~``size``), each alone in a cell of a
    grid whose centre lies ``distance`` from the origin along a random direction: (TriangleMesh, cell size)."""
    cell = 8.0 * size
    grid = np.stack(np.unravel_index(np.arange(count), (int(np.ceil(count ** (1 / 3))),) * 3), -1) * cell
    centre = rng.normal(size=3)
    centre *= distance / np.linalg.norm(centre)
    local = rng.uniform(-size, size, (count, 3, 3))
    local[:, :, 2] *= rng.choice([0.0, 1.0], size=(count, 1))  # half of them axis-aligned in their frame
    rotate = np.where(rng.uniform(size=(count, 1, 1)) < 0.5, random_rotations(rng, count), np.eye(3))
    vertices = (np.einsum("fij,fvj->fvi", rotate, local) + (grid + centre)[:, None, :]).reshape(-1, 3)
    mesh = TriangleMesh(vertices, np.arange(3 * count).reshape(-1, 3), np.zeros(count), np.zeros(count))
    return mesh, cell


def hit_points(rng, mesh, prim):
    u = rng.uniform(size=(2, prim.size)).astype(np.float32)
    b1, b2 = np.where(u.sum(0) > 1, 1 - u, u)
    return mesh.hit_geometry(prim, b1, b2)


def directions_at(rng, normal, cos):
    """Unit directions at cosine ``cos`` (signed) to ``normal``, random azimuth."""
    tangent = np.cross(normal.T, rng.normal(size=normal.T.shape)).T
    tangent /= np.linalg.norm(tangent, axis=0)
    sin = np.sqrt(1 - cos * cos)
    return (normal * cos + tangent * sin).astype(np.float32)


@pytest.mark.parametrize("distance", [0.0, 1e2, 1e4])
@pytest.mark.parametrize("size", [1e-3, 1.0, 1e3])
def test_rays_leaving_a_surface_never_hit_it_again(distance, size):
    rng = np.random.default_rng(7)
    mesh, _ = triangles_in_cells(rng, 512, distance * size, size)
    accel = Accel(mesh.vertices.astype(np.float32), mesh.indices)
    n = 40_000
    prim = rng.integers(0, mesh.triangle_count, n)
    p, normal, eps = hit_points(rng, mesh, prim)
    # grazing to normal incidence, on both sides: |cos| log-uniform in [1e-6, 1]
    cos = np.exp(rng.uniform(np.log(1e-6), 0.0, n)) * rng.choice([-1.0, 1.0], n)
    w = directions_at(rng, normal.astype(np.float64), cos)
    hits = accel.intersect(offset_origin(p, normal, eps, w), w, normals=False)
    assert not np.any(hits.prim == prim), f"{np.count_nonzero(hits.prim == prim)} self-intersections of {n}"


@pytest.mark.parametrize("distance", [0.0, 1e2, 1e4])
def test_shadow_rays_between_visible_points_are_never_blocked_by_their_ends(distance):
    """Two triangles in a cell: any point of one sees any point of the other, unless one point lies
    within the other triangle's error bound of its plane (then the geometry is not resolved in float32:
    such pairs are left out)."""
    rng = np.random.default_rng(11)
    mesh, _ = triangles_in_cells(rng, 1024, distance, 1.0)
    pairs = mesh.triangle_count // 2
    first, second = 2 * np.arange(pairs), 2 * np.arange(pairs) + 1
    # move each odd triangle into its even neighbour's cell, 0.01 .. 2 away along a random direction
    shift = mesh.table[0:3, first].astype(np.float64) - mesh.table[0:3, second]
    offset = rng.normal(size=(3, pairs))
    offset *= np.exp(rng.uniform(np.log(0.01), np.log(2.0), pairs)) / np.linalg.norm(offset, axis=0)
    vertices = mesh.vertices.copy().reshape(-1, 3, 3)
    vertices[1::2] += (shift + offset).T[:, None, :]
    mesh = TriangleMesh(vertices.reshape(-1, 3), mesh.indices, mesh.material, mesh.shape)
    scene = SimpleNamespace(accel=Accel(mesh.vertices.astype(np.float32), mesh.indices))
    k = np.repeat(np.arange(pairs), 40)
    a, n_a, eps_a = hit_points(rng, mesh, first[k])
    b, n_b, eps_b = hit_points(rng, mesh, second[k])
    apart = ((np.abs(dot(a - mesh.table[0:3, second[k]], n_b)) > 4 * eps_b)
             & (np.abs(dot(b - mesh.table[0:3, first[k]], n_a)) > 4 * eps_a))
    a, n_a, eps_a, b, n_b, eps_b = (x[..., apart] for x in (a, n_a, eps_a, b, n_b, eps_b))
    blocked = segment_blocked(scene, a, eps_a, n_a, b, eps_b, n_b)
    assert blocked.size > 10_000 and not blocked.any(), f"{np.count_nonzero(blocked)} of {blocked.size} blocked"
    # and in the other direction
    assert not segment_blocked(scene, b, eps_b, n_b, a, eps_a, n_a).any()


@pytest.mark.parametrize("gap", [1e-6, 1e-5])
def test_a_surface_a_millionth_in_front_of_a_point_blocks_it(gap):
    """Shadow rays toward points on a quad are blocked by a parallel quad ``gap`` in front of it (scene of
    size 1 around the render origin), from every angle down to a cosine of 0.01."""
    rng = np.random.default_rng(3)
    quad = [[-0.5, 0.0, -0.5], [0.5, 0.0, -0.5], [0.5, 0.0, 0.5], [-0.5, 0.0, 0.5]]
    blocker = np.array(quad) * 2 + [0.0, gap, 0.0]
    vertices = np.concatenate([quad, blocker])
    faces = np.array([[0, 2, 1], [0, 3, 2], [4, 6, 5], [4, 7, 6]])  # both facing +y
    mesh = TriangleMesh(vertices, faces, np.zeros(4), np.zeros(4))
    scene = SimpleNamespace(accel=Accel(mesh.vertices.astype(np.float32), mesh.indices))
    n = 20_000
    b, n_b, eps_b = hit_points(rng, mesh, rng.integers(0, 2, n))
    cos = np.exp(rng.uniform(np.log(0.01), 0.0, n))
    a = (b + directions_at(rng, n_b.astype(np.float64), cos) * rng.uniform(0.05, 1.0, n)).astype(np.float32)
    blocked = segment_blocked(scene, a, np.zeros(n, np.float32), np.zeros((3, n), np.float32), b, eps_b, n_b)
    assert blocked.all(), f"{np.count_nonzero(~blocked)} of {n} leak through a surface {gap:g} in front"
    assert np.all(eps_b < gap)


def test_a_ray_starting_in_another_surfaces_plane_does_not_hit_it_at_distance_zero():
    """A point on one wall at its seam with another, moved along its own normal, can lie exactly in the other
    wall's float32 plane; a ray from it into that wall must not report a hit at t = 0 (an infinite geometry
    term: the NaN MIS weights once seen in the Cornell box's light walks)."""
    from pathspace.estimators.walk import WALK_FIELDS, Dimensions, Walk
    from pathspace.estimators.wavefront import Lanes
    from pathspace.roulette import RussianRoulette
    from pathspace.sampler import StreamSamplers

    data = {"camera": {"position": [0.0, 0.0, 0.0], "look_at": [0.0, 0.0, -1.0], "fov": 40, "resolution": [4, 4]},
            "materials": {"white": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
            "shapes": [{"type": "triangles", "material": "white",   # the back wall, z = -1
                        "vertices": [[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1]],
                        "triangles": [[0, 1, 2], [0, 2, 3]]}]}
    scene = ps.scene_from_dict(data)
    assert np.all(scene.origin == 0.0)
    n = 5
    origin = np.array([[0.25] * n, [0.0] * n, [-1.0] * n], np.float32)   # exactly in the wall's plane
    direction = np.array([[0.0] * n, [0.6] * n, [-0.8] * n], np.float32)  # into (through) the wall
    assert scene.accel.intersect(origin, direction, 0.0).t[0] == 0.0     # what Embree reports from t = 0
    lanes = Lanes(WALK_FIELDS, depth=np.zeros(n, np.int32), origin=origin, direction=direction,
                  beta=np.ones((3, n)), pdf=np.ones(n), delta=np.zeros(n, bool))
    walk = Walk(scene, lanes, StreamSamplers(0).open([(0,)], [n]), RussianRoulette("off", 1, 0.5, 1.0),
                Dimensions(bsdf=3))
    assert np.all(walk.trace().prim < 0)


def reference_occluded_between(accel, a, n_a, eps_a, b, n_b, eps_b, lanes=None, b_lanes=None, *, threads=0):
    """:meth:`Accel.occluded_between` in NumPy: the rays of :func:`pathspace.vecmath.shadow_ray`, traced."""
    b_lanes = lanes if b_lanes is None else b_lanes
    if lanes is not None:
        a, n_a, eps_a = (np.take(x, lanes, axis=-1) for x in (a, n_a, eps_a))
    if b_lanes is not None:
        b, n_b, eps_b = (np.take(x, b_lanes, axis=-1) for x in (b, n_b, eps_b))
    origin, direction, tmax = shadow_ray(a, n_a, eps_a, b, n_b, eps_b)
    return Accel.occluded(accel, origin, direction, RAY_TMIN, tmax, threads=threads)


@pytest.mark.parametrize("distance", [0.0, 1e2, 1e4])
def test_shadow_rays_built_in_c_are_the_numpy_references(distance):
    """``Accel.occluded_between`` builds the rays of ``shadow_ray`` in C: on segments between points on random
    triangles (many blocked, many clear, ends on the surfaces they join, at every angle; some points off
    surfaces, some lanes gathered in C) its answers are, one by one, those of the NumPy reference's rays."""
    rng = np.random.default_rng(5)
    mesh, _ = triangles_in_cells(rng, 2048, distance, 1.0)
    accel = Accel(mesh.vertices.astype(np.float32), mesh.indices)
    n = 100_000
    a, n_a, eps_a = hit_points(rng, mesh, rng.integers(0, mesh.triangle_count, n))
    b, n_b, eps_b = hit_points(rng, mesh, rng.integers(0, mesh.triangle_count, n))
    near = rng.uniform(size=n) < 0.3     # b close to a (1e-4 .. 1 apart, more far from the origin), grazing too
    step = directions_at(rng, n_a[:, near].astype(np.float64), rng.uniform(-1.0, 1.0, near.sum()))
    shortest = 1e-4 * max(1.0, distance / 100.0)
    b[:, near] = a[:, near] + step * np.exp(rng.uniform(np.log(shortest), 0.0, near.sum())).astype(np.float32)
    off = rng.uniform(size=n) < 0.1      # points off surfaces (lights, the lens): no normal, no error bound
    n_a[:, off], eps_a[off] = 0.0, 0.0
    camera = rng.uniform(size=n) < 0.1   # far ends off surfaces but with a normal (a thin lens' axis)
    eps_b[camera] = 0.0
    segments = (a, n_a, eps_a, b, n_b, eps_b)
    found = accel.occluded_between(*segments)
    expected = reference_occluded_between(accel, *segments)
    assert 0.03 < found.mean() < 0.97 and np.array_equal(found, expected), np.count_nonzero(found != expected)
    lanes = np.sort(rng.choice(n, n // 3, replace=False))
    assert np.array_equal(accel.occluded_between(*segments, lanes), expected[lanes])
    # The far ends from arrays of their own, through indices of their own (b_lanes): b in another order and width.
    order = rng.permutation(n)
    wider = [np.concatenate([np.take(x, order, axis=-1), np.take(x, order[:7], axis=-1)], axis=-1)
             for x in (b, n_b, eps_b)]
    b_lanes = np.argsort(order)[lanes]
    assert np.array_equal(accel.occluded_between(a, n_a, eps_a, *wider, lanes, b_lanes), expected[lanes])
    assert np.array_equal(accel.occluded_between(a[:, lanes], n_a[:, lanes], eps_a[lanes], *wider, None, b_lanes),
                          expected[lanes])
    # The rays themselves, bit for bit (signed zeros too).
    for built, reference in zip(_native.shadow_rays(*segments, lanes), shadow_ray(*(np.take(x, lanes, axis=-1)
                                                                                     for x in segments))):
        assert built.dtype == reference.dtype == np.float32
        np.testing.assert_array_equal(built.view(np.int32), reference.view(np.int32))
    assert _native.SHADOW_RAY_TMIN == float(RAY_TMIN)


def test_renders_are_the_same_with_shadow_rays_built_in_numpy(monkeypatch):
    """Images are bit for bit the same when every shadow ray is built by the NumPy reference instead of in C."""
    scene = ps.scene_from_dict(scene_dict("cornell-box-specular", (24, 24)))
    renders = [("pt", {}), ("lt", {}), ("bdpt", {}), ("mlt", {"max_depth": 5, "bootstrap": 256, "chains": 128})]
    fast = [ps.render(scene, name, spp=4, seed=9, **params).image for name, params in renders]
    monkeypatch.setattr(Accel, "occluded_between", reference_occluded_between)
    for (name, params), image in zip(renders, fast):
        np.testing.assert_array_equal(ps.render(scene, name, spp=4, seed=9, **params).image, image, err_msg=name)


def test_bad_segments_are_refused_with_their_index():
    accel = Accel(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), np.array([[0, 1, 2]], np.uint32))
    a, n = np.zeros((3, 2), np.float32), np.zeros((3, 2), np.float32)
    eps = np.zeros(2, np.float32)
    with pytest.raises(ValueError, match="invalid shadow ray 1: the segment from"):
        accel.occluded_between(a, n, eps, np.array([[1, 0], [1, 0], [1, 0]], np.float32), n, eps)   # b = a
    with pytest.raises(TypeError, match="b must have dtype float32"):
        accel.occluded_between(a, n, eps, a.astype(np.float64), n, eps)
    with pytest.raises(IndexError, match="lanes"):
        accel.occluded_between(a, n, eps, a + 1, n, eps, np.array([0, 2]))
    with pytest.raises(ValueError, match="eps_a must have shape"):       # a 0-d array
        _native.Accel.occluded_between(accel, a, n, np.array(0, np.float32), a + 1, n, eps)
    with pytest.raises(ValueError, match="n_b has N = 3, but a has N = 2"):
        accel.occluded_between(a, n, eps, a + 1, np.zeros((3, 3), np.float32), eps)
    b3, n3, eps3 = np.ones((3, 3), np.float32), np.zeros((3, 3), np.float32), np.zeros(3, np.float32)
    assert accel.occluded_between(a, n, eps, b3, n3, eps3, None, np.array([2, 0])).shape == (2,)
    with pytest.raises(IndexError, match=r"b_lanes\[1\] = 3 is outside 0 .. 2"):
        accel.occluded_between(a, n, eps, b3, n3, eps3, None, np.array([2, 3]))
    with pytest.raises(ValueError, match="b_lanes has 3 segments, but lanes \\(or a\\) 2"):
        accel.occluded_between(a, n, eps, b3, n3, eps3, None, np.array([2, 0, 1]))
    with pytest.raises(ValueError, match="n_b has N = 2, but b has N = 3"):
        accel.occluded_between(a, n, eps, b3, n, eps3, None, np.array([2, 0]))
    b_wide = np.array([[1, 0, 2], [1, 0, 3], [1, 0, 4]], np.float32)   # its lane 1 is a's point: no segment
    with pytest.raises(ValueError, match=r"invalid shadow ray 1: the segment from \(0, 0, 0\) to \(0, 0, 0\)"):
        accel.occluded_between(a, n, eps, b_wide, n3, eps3, None, np.array([2, 1]))
    with pytest.raises(TypeError, match="b_lanes must be a contiguous int64 array"):
        _native.Accel.occluded_between(accel, a, n, eps, b3, n3, eps3, None, np.array([2, 0], np.int32))


def test_shadow_rays_built_in_c_end_where_the_numpy_references_do():
    """Segments ending on quads with a parallel blocker a few float32 roundings in front (1e-8 .. 1e-4 away):
    whether a segment is blocked hangs on its end offset and on the slack of its tmax, and the C rays answer as
    the NumPy reference's, one by one (a slack off by a quarter flips some)."""
    rng = np.random.default_rng(13)
    cells = 1000
    corner = np.stack(np.unravel_index(np.arange(cells), (10, 10, 10)), -1) * 2.0 - 10.0
    gap = np.exp(rng.uniform(np.log(1e-8), np.log(1e-4), cells))
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]], np.float64)
    vertices = np.concatenate([corner[:, None] + quad, corner[:, None] + quad + gap[:, None, None] * [0, 1, 0]], 1)
    faces = np.array([[0, 2, 1], [0, 3, 2], [4, 6, 5], [4, 7, 6]])
    mesh = TriangleMesh(vertices.reshape(-1, 3), (faces + 8 * np.arange(cells)[:, None, None]).reshape(-1, 3),
                        np.zeros(4 * cells), np.zeros(4 * cells))
    accel = Accel(mesh.vertices.astype(np.float32), mesh.indices)
    n = 100_000
    base = 4 * rng.integers(0, cells, n) + rng.integers(0, 2, n)      # a triangle of a cell's lower quad
    b, n_b, eps_b = hit_points(rng, mesh, base)
    up = directions_at(rng, n_b.astype(np.float64), np.exp(rng.uniform(np.log(0.05), 0.0, n)))
    a = (b + up * rng.uniform(0.05, 0.5, n).astype(np.float32)).astype(np.float32)
    segments = (a, np.zeros((3, n), np.float32), np.zeros(n, np.float32), b, n_b, eps_b)
    found = accel.occluded_between(*segments)
    assert 0.1 < found.mean() < 0.9
    assert np.array_equal(found, reference_occluded_between(accel, *segments))
