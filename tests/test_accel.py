"""Accel (the C extension over Embree 4) agrees exactly with embreex and rejects bad input."""
from __future__ import annotations

import numpy as np
import pytest
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

import pathspace as ps
from pathspace import Accel
from conftest import ROOT


def embreex_run(vertices, indices, origins, directions, query="INTERSECT"):
    scene = rtcore_scene.EmbreeScene(robust=True)
    TriangleMesh(scene, vertices, indices.astype(np.int32))
    if query == "INTERSECT":
        return scene.run(origins, directions, output=1)
    return scene.run(origins, directions, query="OCCLUDED")


def random_soup(rng, triangles=2000):
    vertices = rng.uniform(-1, 1, (3 * triangles, 3)).astype(np.float32)
    indices = np.arange(3 * triangles, dtype=np.uint32).reshape(-1, 3)
    return vertices, indices


def random_rays(rng, n, spread=2.0):
    origins = rng.uniform(-spread, spread, (n, 3)).astype(np.float32)
    directions = rng.normal(size=(n, 3)).astype(np.float32)
    return origins, directions


def assert_same_hits(vertices, indices, origins, directions):
    ref = embreex_run(vertices, indices, origins, directions)
    ours = Accel(vertices, indices).intersect(origins.T, directions.T)
    hit = ref["primID"] >= 0
    assert hit.sum() > 0.05 * len(hit) and (~hit).sum() > 0.05 * len(hit)  # both cases exercised
    np.testing.assert_array_equal(ours.prim, np.where(hit, ref["primID"], -1))
    np.testing.assert_array_equal(ours.t[hit], ref["tfar"][hit])
    np.testing.assert_array_equal(ours.u[hit], ref["u"][hit])
    np.testing.assert_array_equal(ours.v[hit], ref["v"][hit])
    np.testing.assert_array_equal(ours.ng.T[hit], ref["Ng"][hit])
    assert np.all(np.isinf(ours.t[~hit]))
    occluded_ref = embreex_run(vertices, indices, origins, directions, "OCCLUDED") >= 0
    np.testing.assert_array_equal(Accel(vertices, indices).occluded(origins.T, directions.T), occluded_ref)


def test_matches_embreex_on_random_mesh():
    rng = np.random.default_rng(1)
    vertices, indices = random_soup(rng)
    origins, directions = random_rays(rng, 100_000)
    assert_same_hits(vertices, indices, origins, directions)


def test_matches_embreex_on_cornell_box(cornell):
    rng = np.random.default_rng(2)
    vertices = cornell.to_world(cornell.mesh.vertices).astype(np.float32)  # the box in [-1, 1]^3
    origins = rng.uniform(-0.99, 0.99, (100_000, 3)).astype(np.float32)
    # Half the rays from inside the box, half from outside (the camera side, some miss).
    origins[::2] += np.array([0.0, 0.0, 2.5], dtype=np.float32)
    directions = rng.normal(size=(100_000, 3)).astype(np.float32)
    assert_same_hits(vertices, cornell.mesh.indices, origins, directions)


def test_tmin_tmax_and_threads_are_respected():
    rng = np.random.default_rng(3)
    vertices, indices = random_soup(rng, 500)
    origins, directions = random_rays(rng, 50_000)
    accel = Accel(vertices, indices)
    full = accel.intersect(origins.T, directions.T)
    hit = full.prim >= 0
    # A segment ending just before the closest hit sees nothing; one past it sees it.
    tmax = np.where(hit, full.t * 0.999, 1.0).astype(np.float32)
    assert np.all(accel.intersect(origins.T, directions.T, 0.0, tmax).prim[hit] == -1)
    short = accel.occluded(origins.T, directions.T, 0.0, tmax)
    beyond = accel.occluded(origins.T, directions.T, 0.0, np.where(hit, full.t * 1.001, 1.0))
    assert not short[hit].any()
    assert beyond[hit].all()
    # tmin past the closest hit finds a farther one (or none), never a nearer one.
    later = accel.intersect(origins.T, directions.T, np.where(hit, full.t * 1.001, 0.0), np.inf)
    assert np.all(later.t[hit] > full.t[hit])
    # float64 inputs, strided views and any thread count give the same answer.
    o64 = np.asfortranarray(origins.T.astype(np.float64))
    for threads in (1, 2, 3):
        again = accel.intersect(o64, directions.T, threads=threads)
        np.testing.assert_array_equal(again.prim, full.prim)
        np.testing.assert_array_equal(again.t, full.t)


def test_empty_mesh_and_empty_batch():
    accel = Accel(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint32))
    hits = accel.intersect(np.zeros((3, 4), np.float32), np.ones((3, 4), np.float32))
    assert np.all(hits.prim == -1) and np.all(np.isinf(hits.t))
    empty = accel.intersect(np.zeros((3, 0)), np.zeros((3, 0)))
    assert empty.t.shape == (0,) and empty.ng.shape == (3, 0)


@pytest.mark.parametrize("vertices, indices, error, match", [
    (np.zeros((3, 3), np.float64), np.zeros((1, 3), np.uint32), TypeError, "vertices must have dtype float32"),
    (np.zeros((3, 3), np.float32), np.zeros((1, 3), np.int64), TypeError, "indices must have dtype uint32"),
    (np.zeros((3, 2), np.float32), np.zeros((1, 3), np.uint32), ValueError, r"shape \(M, 3\)"),
    (np.zeros((3, 3), np.float32)[:, ::-1], np.zeros((1, 3), np.uint32), ValueError, "C-contiguous"),
    (np.zeros((3, 3), np.float32), np.array([[0, 1, 3]], np.uint32), ValueError, "refers to vertex 3"),
    (np.array([[0, 0, 0], [1, 0, 0], [0, np.nan, 0]], np.float32), np.array([[0, 1, 2]], np.uint32), ValueError,
     "vertex 2 has a non-finite"),
    ([[0, 0, 0]], np.zeros((1, 3), np.uint32), TypeError, "NumPy float32 array"),
])
def test_constructor_validation(vertices, indices, error, match):
    with pytest.raises(error, match=match):
        Accel(vertices, indices)


def test_query_validation():
    accel = Accel(np.eye(3, dtype=np.float32), np.array([[0, 1, 2]], np.uint32))
    ok = np.ones((3, 5), np.float32)
    with pytest.raises(ValueError, match=r"shape \(3, N\).*transpose"):
        accel.intersect(np.ones((5, 3), np.float32), np.ones((5, 3), np.float32))
    with pytest.raises(TypeError, match="float32 or float64"):
        accel.intersect(ok.astype(np.int32), ok)
    with pytest.raises(ValueError, match="origins has 5 rays but directions has 4"):
        accel.intersect(ok, ok[:, :4])
    with pytest.raises(ValueError, match="tmax has 3 entries"):
        accel.occluded(ok, ok, 0.0, np.ones(3))
    bad = ok.copy()
    bad[1, 3] = np.nan
    with pytest.raises(ValueError, match="invalid ray 3: its origin or direction is not finite"):
        accel.intersect(bad, ok)
    zero = ok.copy()
    zero[:, 2] = 0
    with pytest.raises(ValueError, match="invalid ray 2: its direction is the zero vector"):
        accel.occluded(ok, zero)
    with pytest.raises(ValueError, match="tmin must be finite and >= 0"):
        accel.intersect(ok, ok, -1.0)
    with pytest.raises(ValueError, match="tmax is NaN"):
        accel.intersect(ok, ok, 0.0, np.nan)
    with pytest.raises(ValueError, match="threads must be between 0"):
        accel.intersect(ok, ok, threads=-1)
    with pytest.raises(ValueError, match="threads must be between 0"):
        accel.threads = 100_000
    # Values that are finite in float64 but not in float32 are rejected, not traced as silent misses.
    huge = ok.astype(np.float64)
    huge[0, 1] = 1e39
    with pytest.raises(ValueError, match="invalid ray 1: its origin or direction is not finite in float32"):
        accel.intersect(huge, ok)
    tiny = ok.astype(np.float64) * 1e-50
    with pytest.raises(ValueError, match="invalid ray 0: its direction is the zero vector"):
        accel.occluded(ok, tiny)


def test_missing_embreex_is_reported_plainly(monkeypatch):
    import importlib.metadata

    from pathspace import accel

    def no_package(name):
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "files", no_package)
    with pytest.raises(ImportError, match="bundled in the 'embreex' wheel, which is not installed"):
        accel.embree_library_path()


def edge_aimed_rays(vertices, indices, rng, n):
    """Rays from inside a closed mesh's bounds toward points on its triangles' edges (a tenth at vertices)."""
    vertices = vertices.astype(np.float64)
    triangle, corner = rng.integers(0, len(indices), n), rng.integers(0, 3, n)
    a, b = vertices[indices[triangle, corner]], vertices[indices[triangle, (corner + 1) % 3]]
    along = np.where(rng.random(n) < 0.1, 0.0, rng.random(n))[:, None]
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    origins = lo + (hi - lo) * rng.uniform(0.05, 0.95, (n, 3))
    directions = a + along * (b - a) - origins
    return np.ascontiguousarray(origins.T, np.float32), np.ascontiguousarray(directions.T, np.float32)


def test_watertight_build_lets_no_ray_through_the_edges_of_a_closed_box():
    scene = ps.load_scene(ROOT / "scenes" / "furnace" / "scene.toml")   # a closed cube, 12 triangles
    vertices = scene.mesh.vertices.astype(np.float32)
    origins, directions = edge_aimed_rays(vertices, scene.mesh.indices, np.random.default_rng(4), 200_000)
    watertight = Accel(vertices, scene.mesh.indices)
    assert watertight.watertight and "watertight=True" in repr(watertight)
    assert np.all(watertight.intersect(origins, directions).prim >= 0)
    assert watertight.occluded(origins, directions).all()
    # Without the robust build, Embree's faster arithmetic lets some of these rays slip through an edge: what
    # the default guards against (docs/performance.md has the rates on the shipped scenes).  This is also the
    # check that watertight=False reaches Embree; should a later Embree be watertight without its robust mode,
    # the test fails, and the trade described in the docs is gone.
    fast = Accel(vertices, scene.mesh.indices, watertight=False)
    assert not fast.watertight
    assert np.count_nonzero(fast.intersect(origins, directions).prim < 0) > 0


def test_fast_build_finds_the_watertight_hits_of_ordinary_rays(cornell):
    rng = np.random.default_rng(5)
    vertices = cornell.mesh.vertices.astype(np.float32)
    origins = cornell.mesh.vertices.mean(axis=0) + rng.uniform(-0.9, 0.9, (200_000, 3))
    origins, directions = origins.T.astype(np.float32), rng.normal(size=(3, 200_000)).astype(np.float32)
    watertight = Accel(vertices, cornell.mesh.indices).intersect(origins, directions)
    fast_accel = Accel(vertices, cornell.mesh.indices, watertight=False)
    fast = fast_accel.intersect(origins, directions)
    # The same surfaces at the same distances (where the box stands on the floor, coplanar triangles tie and
    # either build may report either of them).
    hit = watertight.prim >= 0
    assert 0.7 < hit.mean() < 0.95   # the box is open toward the camera
    np.testing.assert_array_equal(fast.prim >= 0, hit)
    np.testing.assert_allclose(fast.t[hit], watertight.t[hit], rtol=1e-4)
    assert np.count_nonzero(fast.prim != watertight.prim) < 1e-3 * hit.size
    # Occlusion of the segments up to just before and just past the watertight hits.
    for scale, expected in ((0.99, False), (1.01, True)):
        tmax = np.where(hit, watertight.t * scale, 1.0).astype(np.float32)
        assert np.all(fast_accel.occluded(origins, directions, 0.0, tmax)[hit] == expected)


def test_fast_queries_leave_the_callers_floating_point_modes_alone():
    # The fast build traces with denormals flushed to zero; the calling thread (threads=1 traces on it) must
    # get its own modes back, or NumPy's arithmetic after a query would flush denormals too.
    accel = Accel(np.eye(3, dtype=np.float32), np.array([[0, 1, 2]], np.uint32), watertight=False)
    rays = np.ones((3, 5000), np.float32)
    accel.intersect(-rays, rays, threads=1)
    accel.occluded(-rays, rays, threads=1)
    tiny = np.array([1e-38], np.float32)
    assert (tiny / np.float32(1000))[0] > 0   # a denormal float32, not flushed
    assert np.float64(1e-308) / 1e10 > 0
