"""The C extension (pathspace._native) given malformed input: every entry point answers a wrong dtype,
shape, stride, alignment, length, NaN/Inf or out-of-range value with a Python exception naming the
argument and what was expected, or with a correct result (odd but valid layouts: strided, negative-stride,
broadcast and unaligned arrays; empty meshes and batches) -- never a crash or garbage.  These tests also
run under AddressSanitizer (.ci/asan)."""
from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from pathspace import Accel, _native
from pathspace.accel import embree_library_path

# Two triangles in the plane z = 0 covering [0, 1]^2, and rays straight down onto them (and beside them).
QUAD_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
QUAD_F = np.array([[0, 1, 2], [0, 2, 3]], np.uint32)


def down_rays(n=64, seed=0):
    """(3, n) origins above z = 0 (a quarter of them beside the quad) and (3, n) directions straight down."""
    rng = np.random.default_rng(seed)
    origins = np.vstack([rng.uniform(-0.5, 1.5, n), rng.uniform(0, 1, n), np.full(n, 2.0)]).astype(np.float32)
    directions = np.tile(np.array([[0], [0], [-1]], np.float32), (1, n))
    return origins, directions


@pytest.fixture(scope="module")
def accel():
    return Accel(QUAD_V, QUAD_F)


@pytest.fixture(scope="module")
def reference(accel):
    origins, directions = down_rays()
    hits = accel.intersect(origins, directions)
    inside = (origins[0] >= 0) & (origins[0] <= 1)
    assert np.array_equal(hits.prim >= 0, inside) and np.allclose(hits.t[inside], 2.0)
    return origins, directions, hits


# -- Accel constructor ---------------------------------------------------------------------------------


def unaligned(array):
    """A copy of ``array`` whose data starts one byte past an aligned address (C-contiguous, not aligned)."""
    raw = np.zeros(array.nbytes + 1, np.uint8)
    view = raw[1:].view(array.dtype).reshape(array.shape)
    view[...] = array
    assert not view.flags.aligned and view.flags.c_contiguous
    return view


@pytest.mark.parametrize("vertices, indices, error, match", [
    (QUAD_V.astype(np.float16), QUAD_F, TypeError, r"vertices must have dtype float32, got dtype\('float16'\)"),
    (QUAD_V.astype(object), QUAD_F, TypeError, "vertices must have dtype float32"),
    (QUAD_V.astype(">f4"), QUAD_F, TypeError, "vertices must have dtype float32"),
    (QUAD_V, QUAD_F.astype(np.int32), TypeError, "indices must have dtype uint32"),
    (QUAD_V, QUAD_F.astype(np.float32), TypeError, "indices must have dtype uint32"),
    (QUAD_V.ravel(), QUAD_F, ValueError, r"vertices must have shape \(M, 3\), got ndim=1"),
    (QUAD_V[None], QUAD_F, ValueError, r"vertices must have shape \(M, 3\), got ndim=3"),
    (np.zeros((4, 4), np.float32), QUAD_F, ValueError, r"vertices must have shape \(M, 3\)"),
    (QUAD_V, QUAD_F[:, :2].copy(), ValueError, r"indices must have shape \(M, 3\)"),
    (np.asfortranarray(QUAD_V), QUAD_F, ValueError, "vertices must be C-contiguous and aligned"),
    (QUAD_V[::-1], QUAD_F, ValueError, "vertices must be C-contiguous"),
    (QUAD_V, np.asfortranarray(QUAD_F), ValueError, "indices must be C-contiguous"),
    (unaligned(QUAD_V), QUAD_F, ValueError, r"vertices must be C-contiguous and aligned \(use numpy.require"),
    (QUAD_V, unaligned(QUAD_F), ValueError, "indices must be C-contiguous and aligned"),
    (np.where([[False], [True], [False], [False]], np.inf, QUAD_V).astype(np.float32), QUAD_F, ValueError,
     "vertex 1 has a non-finite coordinate"),
    (QUAD_V, np.array([[0, 1, 4]], np.uint32), ValueError, "triangle 0 refers to vertex 4 but there are only 4"),
    (QUAD_V, np.array([[0, 1, 2], [0, 2, 2 ** 32 - 1]], np.uint32), ValueError,
     "triangle 1 refers to vertex 4294967295"),
    (np.zeros((0, 3), np.float32), QUAD_F, ValueError, "refers to vertex 0 but there are only 0 vertices"),
    (QUAD_V.tolist(), QUAD_F, TypeError, "vertices must be a NumPy float32 array of shape \\(M, 3\\), got list"),
    (QUAD_V, None, TypeError, "indices must be a NumPy uint32 array of shape \\(M, 3\\), got NoneType"),
])
def test_constructor_rejects_malformed_meshes(vertices, indices, error, match):
    with pytest.raises(error, match=match):
        Accel(vertices, indices)


def test_constructor_threads_and_initialisation():
    with pytest.raises(ValueError, match=r"threads must be between 0 \(all available cores\) and 256, got 257"):
        Accel(QUAD_V, QUAD_F, threads=257)
    with pytest.raises(OverflowError):
        Accel(QUAD_V, QUAD_F, threads=2 ** 40)
    with pytest.raises(TypeError):
        Accel(QUAD_V, QUAD_F, threads="2")
    accel = Accel(QUAD_V, QUAD_F, threads=1)
    with pytest.raises(RuntimeError, match="Accel is already initialised"):
        _native.Accel.__init__(accel, QUAD_V, QUAD_F)
    bare = _native.Accel.__new__(_native.Accel)  # never initialised
    with pytest.raises(RuntimeError, match="Accel was not initialised"):
        bare.intersect(*down_rays(4))
    with pytest.raises(RuntimeError, match="Accel was not initialised"):
        bare.occluded(*down_rays(4))
    with pytest.raises(AttributeError, match="cannot be deleted"):
        del accel.threads
    with pytest.raises(TypeError):
        accel.threads = "2"
    accel.threads = 0  # back to every core
    assert accel.threads == _native.default_thread_count()
    assert (accel.triangle_count, accel.vertex_count) == (2, 4)
    assert repr(accel).startswith("Accel(2 triangles, 4 vertices")


def test_empty_and_degenerate_meshes_are_never_hit():
    origins, directions = down_rays()
    empty = Accel(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint32))
    assert np.all(empty.intersect(origins, directions).prim == -1)
    assert not empty.occluded(origins, directions).any()
    # Unused vertices and no triangles; then zero-area triangles (a point, a segment).
    assert not Accel(QUAD_V, np.zeros((0, 3), np.uint32)).occluded(origins, directions).any()
    degenerate = Accel(QUAD_V, np.array([[0, 0, 0], [0, 1, 1], [0, 1, 0]], np.uint32))
    hits = degenerate.intersect(origins, directions)
    assert np.all(hits.prim == -1) and np.all(np.isinf(hits.t))


# -- queries -------------------------------------------------------------------------------------------


@pytest.mark.parametrize("make", [
    lambda a: a.astype(np.float64),
    lambda a: np.asfortranarray(a),
    lambda a: np.ascontiguousarray(a[:, ::-1])[:, ::-1],  # negative strides
    lambda a: np.repeat(a, 2, axis=1)[:, ::2],  # every other ray of a wider array
    lambda a: unaligned(a.astype(np.float64)),
    lambda a: np.ascontiguousarray(a.T).T,  # (N, 3) memory seen as (3, N)
], ids=["float64", "fortran", "negative-strides", "strided", "unaligned", "transposed"])
def test_any_layout_of_rays_gives_the_same_hits(accel, reference, make):
    origins, directions, hits = reference
    again = accel.intersect(make(origins), make(directions))
    for name in ("t", "prim", "u", "v", "ng"):
        np.testing.assert_array_equal(getattr(again, name), getattr(hits, name))
    np.testing.assert_array_equal(accel.occluded(make(origins), make(directions)), hits.prim >= 0)


def test_broadcast_rays_and_per_ray_bounds(accel):
    # A (3, N) view with stride 0 along the rays: N copies of one ray.
    origin = np.broadcast_to(np.array([[0.5], [0.5], [2.0]], np.float32), (3, 1000))
    direction = np.broadcast_to(np.array([[0.0], [0.0], [-1.0]]), (3, 1000))
    hits = accel.intersect(origin, direction, tmin=np.broadcast_to(np.float32(0.0), (1000,)))
    # Every copy gets the same hit; its distance is 2 within Embree's float32 rounding (its ISA decides the
    # last bit: 1.9999999 on some machines).
    assert np.all(hits.prim >= 0) and np.all(hits.t == hits.t[0]) and abs(hits.t[0] - 2.0) <= 4 * 2.0 ** -23
    # tmax below tmin, and tmax = -inf, are empty intervals: misses, not errors.
    assert np.all(accel.intersect(origin, direction, 3.0, 1.0).prim == -1)
    assert not accel.occluded(origin, direction, 0.0, -np.inf).any()
    # tmax = inf given as a huge float64 (beyond float32) is still unbounded.
    assert accel.occluded(origin, direction, 0.0, 1e300).all()


@pytest.mark.parametrize("origins, error, match", [
    (np.zeros((3, 4), np.int32), TypeError, "origins must be float32 or float64 in native byte order"),
    (np.zeros((3, 4), np.float16), TypeError, "origins must be float32 or float64"),
    (np.zeros((3, 4), np.complex64), TypeError, "origins must be float32 or float64"),
    (np.zeros((3, 4), object), TypeError, "origins must be float32 or float64"),
    (np.zeros((3, 4), bool), TypeError, "origins must be float32 or float64"),
    (np.zeros((3, 4), ">f8"), TypeError, "origins must be float32 or float64 in native byte order"),
    (np.zeros(3, np.float32), ValueError, r"origins must have shape \(3, N\) \(one row per coordinate\), got ndim=1"),
    (np.zeros((3, 4, 1), np.float32), ValueError, r"origins must have shape \(3, N\)"),
    (np.zeros((4, 4), np.float32), ValueError, r"origins must have shape \(3, N\)"),
    (np.zeros((4, 3), np.float32), ValueError, r"with shape \(N, 3\): transpose it"),
    ([[0.0] * 4] * 3, TypeError, r"origins must be a NumPy array of shape \(3, N\), got list"),
])
def test_queries_reject_malformed_origins(accel, origins, error, match):
    directions = np.ones((3, 4), np.float32)
    for query in (accel.intersect, accel.occluded):
        with pytest.raises(error, match=match):
            query(origins, directions)
    with pytest.raises(error, match=match.replace("origins", "directions")):
        accel.intersect(directions, origins)


@pytest.mark.parametrize("tmin, tmax, error, match", [
    (np.zeros(3), np.inf, ValueError, "tmin has 3 entries but there are 4 rays"),
    (0.0, np.zeros((4, 1)), ValueError, r"tmax must be a scalar or an array of shape \(N,\)"),
    (np.zeros(4, np.int64), np.inf, TypeError, "tmin must be float32 or float64 in native byte order"),
    (0.0, np.full(4, np.inf, ">f8"), TypeError, "tmax must be float32 or float64 in native byte order"),
    ("0", np.inf, TypeError, r"tmin must be a number or an array of shape \(N,\), got str"),
    (0.0, None, TypeError, "tmax must be a number or an array"),
    (np.nan, np.inf, ValueError, "invalid ray 0: tmin must be finite and >= 0"),
    (-1e-30, np.inf, ValueError, "invalid ray 0: tmin must be finite and >= 0"),
    (np.inf, np.inf, ValueError, "invalid ray 0: tmin must be finite and >= 0"),
    (1e39, np.inf, ValueError, "invalid ray 0: tmin must be finite and >= 0"),
    (0.0, np.nan, ValueError, "invalid ray 0: tmax is NaN"),
    (np.array([0.0, 0.0, np.nan, 0.0]), np.inf, ValueError, "invalid ray 2: tmin must be finite"),
])
def test_queries_reject_malformed_bounds(accel, tmin, tmax, error, match):
    origins, directions = down_rays(4)
    for query in (accel.intersect, accel.occluded):
        with pytest.raises(error, match=match):
            query(origins, directions, tmin, tmax)


@pytest.mark.parametrize("row, value, match", [
    (0, np.nan, "its origin or direction is not finite in float32"),
    (1, np.inf, "its origin or direction is not finite in float32"),
    (2, -1e39, "its origin or direction is not finite in float32"),  # finite in float64, not in float32
])
@pytest.mark.parametrize("which", ["origins", "directions"])
def test_rays_with_nan_or_inf_are_refused_by_index(accel, row, value, match, which):
    origins, directions = down_rays(8)
    arrays = {"origins": origins.astype(np.float64), "directions": directions.astype(np.float64)}
    arrays[which][row, 5] = value
    for query in (accel.intersect, accel.occluded):
        with pytest.raises(ValueError, match=f"invalid ray 5: {match}"):
            query(arrays["origins"], arrays["directions"])


def test_zero_direction_and_mismatched_batches(accel):
    origins, directions = down_rays(8)
    directions[:, 3] = 0.0
    with pytest.raises(ValueError, match="invalid ray 3: its direction is the zero vector"):
        accel.intersect(origins, directions)
    with pytest.raises(ValueError, match="origins has 8 rays but directions has 7"):
        accel.occluded(origins, directions[:, :7])
    empty = accel.intersect(np.zeros((3, 0), np.float32), np.zeros((3, 0)), np.zeros(0), np.zeros(0))
    assert empty.t.shape == empty.prim.shape == (0,) and empty.ng.shape == (3, 0)
    assert accel.occluded(np.zeros((3, 0)), np.zeros((3, 0))).shape == (0,)
    assert accel.intersect(origins[:, :2], down_rays(2)[1], normals=False).ng is None


def test_query_thread_counts(accel, reference):
    origins, directions, hits = reference
    with pytest.raises(ValueError, match="threads must be between 0 .* and 256, got 1000"):
        accel.intersect(origins, directions, threads=1000)
    with pytest.raises(OverflowError):
        accel.occluded(origins, directions, threads=2 ** 40)
    np.testing.assert_array_equal(accel.intersect(origins, directions, threads=256).prim, hits.prim)


def test_huge_batches_fail_with_memory_error(accel):
    # 2**40 rays as a broadcast view costs nothing; their results (4 TiB each) cannot be allocated.
    origins = np.broadcast_to(np.zeros((3, 1), np.float32), (3, 2 ** 40))
    with pytest.raises(MemoryError):
        accel.intersect(origins, origins)
    with pytest.raises(MemoryError):
        accel.occluded(origins, origins)


# -- MIS weights (ext/mis.c) ---------------------------------------------------------------------------


def mis_arguments(**changes):
    """A valid mis_weights call (one lane: a 2-vertex light subpath and a 2-vertex eye subpath, the
    connections s = 1, t = 2 and s = 2, t = 1), as (positional arguments by name, keyword arguments),
    with some arguments replaced."""
    args = dict(
        s=np.array([1, 2], np.int32), t=np.array([2, 1], np.int32), lane=np.zeros(2, np.int64),
        light_offset=np.array([0, 2], np.int64), light_fwd=np.array([1.0, 2.0]), light_rev=np.array([0.5, 3.0]),
        light_delta=np.zeros(2, np.uint8),
        eye_offset=np.array([0, 2], np.int64), eye_fwd=np.array([1.0, 4.0]), eye_rev=np.array([0.0, 1.5]),
        eye_delta=np.zeros(2, np.uint8), light_flags=np.zeros(2, np.uint8),
        qs_fwd=np.array([1.0, 2.0]), qs_rev=np.array([0.7, 0.9]), qs_minus_rev=np.array([0.0, 0.5]),
        pt_fwd=np.array([4.0, 1.0]), pt_rev=np.array([2.5, 3.0]), pt_minus_rev=np.array([1.5, 0.0]))
    kwargs = dict(camera_is_delta=True, heuristic=1, beta=2.0)
    for key, value in changes.items():
        (args if key in args else kwargs)[key] = value
    return args, kwargs


def mis_weights(args, kwargs):
    """_native.mis_weights called with the arguments of :func:`mis_arguments`."""
    return _native.mis_weights(*args.values(), **kwargs)


def test_mis_weights_valid_call_and_layouts():
    args, kwargs = mis_arguments()
    weights = mis_weights(args, kwargs)
    assert weights.shape == (2,) and np.all((weights > 0) & (weights < 1))
    # Lists, strided and negative-stride views and other integer widths that cast safely give the same.
    args2, _ = mis_arguments(s=[1, 2], t=np.array([2, 2, 1, 1], np.int32)[::2], lane=np.zeros(2, np.int8),
                             qs_fwd=np.array([2.0, 1.0])[::-1], light_delta=np.zeros(2, bool))
    np.testing.assert_array_equal(mis_weights(args2, kwargs), weights)
    empty, _ = mis_arguments(**{name: np.zeros(0, dtype) for name, dtype in [
        ("s", np.int32), ("t", np.int32), ("lane", np.int64), ("light_flags", np.uint8)] + [
        (name, np.float64) for name in ("qs_fwd", "qs_rev", "qs_minus_rev", "pt_fwd", "pt_rev", "pt_minus_rev")]})
    assert mis_weights(empty, kwargs).shape == (0,)


@pytest.mark.parametrize("changes, error, match", [
    (dict(s=np.array([1.0, 2.0])), TypeError, "mis_weights: s must be a 1-D array convertible"),
    (dict(t=np.array([2, 1], np.int64)), TypeError, "mis_weights: t must be a 1-D array convertible"),
    (dict(lane=np.zeros(2, np.uint64)), TypeError, "mis_weights: lane must be a 1-D array"),
    (dict(light_fwd=np.array([1, 2], object)), TypeError, "mis_weights: light_fwd must be a 1-D array"),
    (dict(eye_rev=np.array(["a", "b"])), TypeError, "mis_weights: eye_rev must be a 1-D array"),
    (dict(qs_fwd=np.ones((2, 1))), TypeError, "mis_weights: qs_fwd must be a 1-D array"),
    (dict(pt_rev=1.0), TypeError, "mis_weights: pt_rev must be a 1-D array"),
    (dict(light_flags=np.zeros(3, np.uint8)), ValueError,
     r"light_flags has 3 entries, expected one per connection \(2\)"),
    (dict(pt_minus_rev=np.zeros(1)), ValueError, "pt_minus_rev has 1 entries, expected one per connection"),
    (dict(light_offset=np.zeros(0, np.int64)), ValueError, "light_offset and eye_offset need lanes \\+ 1 entries"),
    (dict(eye_offset=np.array([0, 1, 2], np.int64)), ValueError, "need lanes \\+ 1 entries"),
    (dict(light_fwd=np.ones(3)), ValueError, "subpath arrays disagree with their offsets"),
    (dict(light_offset=np.array([0, 5], np.int64)), ValueError, "subpath arrays disagree with their offsets"),
    # Offsets that would read outside the arrays: negative, or decreasing.
    (dict(light_offset=np.array([-100, 2], np.int64)), ValueError, r"must start at 0 and never decrease \(entry 0"),
    (dict(s=np.array([1, 1], np.int32), light_offset=np.array([0, 5, 2], np.int64), light_fwd=np.ones(2),
          eye_offset=np.array([0, 0, 2], np.int64), lane=np.array([1, 1], np.int64)), ValueError,
     r"must start at 0 and never decrease \(entry 2"),
    (dict(lane=np.array([0, 1], np.int64)), ValueError, r"connection 1 \(lane 1, s=2, t=1\) does not fit"),
    (dict(lane=np.array([-1, 0], np.int64)), ValueError, r"connection 0 \(lane -1, s=1, t=2\) does not fit"),
    (dict(s=np.array([1, 5], np.int32)), ValueError, r"connection 1 \(lane 0, s=5, t=1\) does not fit"),
    (dict(t=np.array([2, 4], np.int32)), ValueError, r"connection 1 \(lane 0, s=2, t=4\) does not fit"),
    (dict(s=np.array([-1, 2], np.int32)), ValueError, "connection 0 .* does not fit"),
    (dict(s=np.array([2 ** 31 - 1, 2], np.int32), t=np.array([2 ** 31 - 1, 1], np.int32)), ValueError,
     "connection 0 .* does not fit"),
    (dict(s=np.array([0, 2], np.int32), t=np.array([1, 1], np.int32)), ValueError,
     r"connection 0 \(lane 0, s=0, t=1\)"),
    (dict(heuristic=7), ValueError, "mis_weights: unknown heuristic code"),
    (dict(beta=np.nan), ValueError, "beta must be finite and > 0"),
    (dict(beta=-1.0), ValueError, "beta must be finite and > 0"),
    (dict(allowed=np.ones((3, 4), np.uint8)), ValueError, r"allowed must be a square \(size, size\) array"),
    (dict(allowed=np.ones(4, np.uint8)), ValueError, "allowed must be a square"),
    (dict(allowed=np.ones((2, 2), np.float64)), ValueError, "allowed must be a square"),
])
def test_mis_weights_rejects_malformed_batches(changes, error, match):
    with pytest.raises(error, match=match):
        mis_weights(*mis_arguments(**changes))


@pytest.mark.parametrize("value", [np.nan, np.inf, -1.0, 1e308, 5e-324])
@pytest.mark.parametrize("name", ["light_fwd", "eye_rev", "qs_rev", "pt_fwd"])
def test_mis_weights_of_odd_densities_are_nan_or_weights(name, value):
    """Densities are not checked (that would cost a pass over every vertex): NaN or negative ones give a
    NaN weight, which the estimators count and drop; infinities and extreme values give weights in [0, 1]."""
    args, kwargs = mis_arguments()
    args[name] = args[name].copy()
    args[name][0] = value
    weights = mis_weights(args, kwargs)
    assert weights.shape == (2,)
    ok = np.isnan(weights) | ((weights >= 0) & (weights <= 1))
    assert ok.all(), weights
    if np.isfinite(value) and value > 0:
        assert np.all(np.isfinite(weights))


def test_mis_weights_huge_subset_table_is_refused_before_use():
    with pytest.raises((ValueError, MemoryError)):
        mis_weights(*mis_arguments(allowed=np.broadcast_to(np.uint8(1), (2 ** 20 + 1, 2 ** 20 + 1))))


# -- module functions ----------------------------------------------------------------------------------


def test_tune_allocator_and_thread_count():
    assert _native.default_thread_count() >= 1
    with pytest.raises(ValueError, match="thresholds must be positive byte counts"):
        _native.tune_allocator(0, 1)
    with pytest.raises(OverflowError):
        _native.tune_allocator(2 ** 40, 1)
    with pytest.raises(TypeError):
        _native.tune_allocator("1", 1)


def run_fresh(code: str) -> str:
    """Run ``code`` in a new interpreter (Embree not yet loaded); return what it prints."""
    done = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_load_embree_before_and_after_loading():
    out = run_fresh(f"""
        import numpy as np
        from pathspace import _native

        def attempt(call, *args):
            try:
                call(*args)
                print("ok")
            except Exception as error:
                print(type(error).__name__, error)

        attempt(_native.Accel, np.zeros((3, 3), np.float32), np.zeros((1, 3), np.uint32))
        attempt(_native.load_embree, "/nonexistent/libembree4.so")
        attempt(_native.load_embree, "libm.so.6")
        attempt(_native.load_embree, "a\\0b")
        attempt(_native.load_embree, {embree_library_path()!r}, "threads=abc,bogus")
        print(_native.embree_loaded())
        attempt(_native.load_embree, {embree_library_path()!r})
        attempt(_native.load_embree, {embree_library_path()!r})
        attempt(_native.load_embree, "libm.so.6")
        print(_native.Accel(np.eye(3, dtype=np.float32), np.array([[0, 1, 2]], np.uint32)).triangle_count)
        """).splitlines()
    assert out[0].startswith("RuntimeError Embree is not loaded: call pathspace._native.load_embree(path) first")
    assert out[1].startswith("ImportError cannot load the Embree 4 library /nonexistent/libembree4.so")
    assert out[2].startswith("ImportError the Embree library libm.so.6 has no symbol rtcNewDevice: it is not Embree 4")
    assert out[3] == "ValueError embedded null character"
    assert out[4].startswith("RuntimeError Embree") and "could not create a device" in out[4]
    assert out[5:8] == ["None", "ok", "ok"]
    assert out[8].startswith("RuntimeError Embree is already loaded from") and "cannot switch to libm.so.6" in out[8]
    assert out[9] == "1"
