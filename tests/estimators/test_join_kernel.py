"""BDPT's fused joins of light and camera vertices (ext/join.c) against the NumPy code they stand for.

``BDPT(kernel="fused")`` joins the vertices of its light and camera subpaths (s, t >= 2,
:mod:`pathspace.estimators.join_fused`) and its light vertices to a pinhole camera (t = 1,
:mod:`pathspace.estimators.lens_fused`) in one C pass each where the scene allows; ``kernel="numpy"`` is the
reference.  Compared bit for bit (as integers): whole renders on scenes with diffuse, mirror and glass surfaces
under several depths, MIS heuristics, diffuse techniques and roulette policies, with both kernels' calls
counted, and the contributions of chosen strategies (multiplexed MLT's); then the joins of made-up vertex pairs
with extreme values (throughputs, densities and survival probabilities over 300 decades and zero, infinite or
NaN; pairs at the same point, far apart or with NaN positions; surfaces seen from both sides and edge-on; zero
and NaN normals; NaN directions), through the shadow rays and without them; then the scenes and settings left to
NumPy, and the kernel's refusals.
"""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace import _native
from pathspace.estimators import connections
from pathspace.estimators.bdpt import BDPT
from pathspace.estimators.bidirectional import STREAMS
from pathspace.estimators.connections import Batch, _join
from pathspace.estimators.join_fused import join_kernel
from pathspace.sampler import ReplaySampler
from pathspace.spectra import RGBColours, SpectralColours
from conftest import count_lanes, made_up_side, nothing_blocked, same_bits
from conftest import repository_scene as scene

DENSITIES = ("qs_fwd", "qs_rev", "qs_minus_rev", "pt_fwd", "pt_rev", "pt_minus_rev")


@pytest.fixture
def kernel_calls(monkeypatch):
    """The numbers of vertex pairs joined, of light vertices joined to the camera and of camera vertices joined to
    light samples by the fused kernels so far (lists of one count each)."""
    return (count_lanes(monkeypatch, "join_vertices", 16), count_lanes(monkeypatch, "lens_connect", 6),
            count_lanes(monkeypatch, "join_light_samples", 9))


CONFIGS = {
    "default": {},
    "short": {"max_depth": 3},
    "balance-uniform-diffuse": {"mis": "balance", "diffuse_sampling": "uniform"},
    "rr-fixed": {"rr": "fixed", "rr_probability": 0.3, "rr_depth": 2},
    "rr-throughput": {"rr": "throughput", "rr_depth": 3},
    "single": {"mis": "single", "strategy": (2, 3)},
}


@pytest.mark.parametrize("config", CONFIGS)
@pytest.mark.parametrize("name", ["cornell-box", "cornell-box-specular"])
def test_fused_bdpt_equals_numpy(name, config, kernel_calls):
    sc = scene(name)
    fused = ps.render(sc, "bdpt", spp=2, seed=5, threads=1, kernel="fused", **CONFIGS[config])
    counts = [calls[0] for calls in kernel_calls]
    assert min(counts) > 0
    numpy = ps.render(sc, "bdpt", spp=2, seed=5, threads=1, kernel="numpy", **CONFIGS[config])
    assert [calls[0] for calls in kernel_calls] == counts
    for what in ("subpath vertices", "light and camera vertices joined", "camera vertices joined to light samples",
                 "light vertices joined to the camera"):
        assert f"{what} in one C pass (a fused kernel) in RGB, in NumPy when spectral" in fused.stats["plan"]
    assert fused.stats["rays"] == numpy.stats["rays"]
    for field in ("scaled_mean", "scaled_m2", "exponent"):
        same_bits(getattr(fused.film.moments, field), getattr(numpy.film.moments, field), field)
    same_bits(fused.image, numpy.image)


@pytest.mark.parametrize("name", ["caustic-glass", "pool", "furnace"])
def test_fused_bdpt_equals_numpy_through_glass(name, kernel_calls):
    sc = scene(name, (16, 16))
    fused = ps.render(sc, "bdpt", spp=2, seed=5, threads=1, pyramid=3)
    assert min(calls[0] for calls in kernel_calls) > 0
    numpy = ps.render(sc, "bdpt", spp=2, seed=5, threads=1, pyramid=3, kernel="numpy")
    same_bits(fused.image, numpy.image)
    assert fused.strategies.keys() == numpy.strategies.keys()
    for strategy, images in fused.strategies.items():
        for kind, image in images.items():
            same_bits(image, numpy.strategies[strategy][kind], f"{strategy} {kind}")


def test_fused_chosen_strategies_equal_numpy(kernel_calls):
    """Multiplexed MLT's contributions: one chosen strategy (s, t) per lane, joined by the same kernels."""
    sc = scene("cornell-box")
    n = 4000
    rng = np.random.default_rng(3)
    pixels = rng.integers(0, sc.camera.width * sc.camera.height, n)
    s = rng.integers(0, 5, n).astype(np.int64)
    t = rng.integers(1, 5, n).astype(np.int64)
    numbers = {name: rng.random((n, 16)) for name in STREAMS}
    rows = {}
    for kernel in ("fused", "numpy"):   # numbers past the 16 given: the same from a generator of the same seed
        samplers = {name: ReplaySampler(numbers[name].copy(), np.random.default_rng(7)) for name in STREAMS}
        rows[kernel] = BDPT(kernel=kernel).evaluate(sc, pixels, samplers, chosen=(s, t))
    assert min(calls[0] for calls in kernel_calls) > 0
    fused, numpy = rows["fused"], rows["numpy"]
    assert ((fused.s >= 2) & (fused.t >= 2)).sum() > 100
    for field in ("lane", "s", "t", "unweighted", "weighted", "weight", "pixel", "raster"):
        same_bits(getattr(fused, field), getattr(numpy, field), field)


# -- the pairs joined -----------------------------------------------------------------------------------------

def pairs_numpy(pair_start, nz, y_start, z_start, cy, cz, light_index, eye_index, begin, end, max_depth):
    """The reference of ``_native.join_pairs``: the pairs begin .. end - 1, enumerated lane by lane in NumPy."""
    k = np.arange(begin, end)
    lane = np.searchsorted(pair_start, k, side="right") - 1
    nth_y, nth_z = np.divmod(k - pair_start[lane], nz[lane])
    y, z = cy[y_start[lane] + nth_y], cz[z_start[lane] + nth_z]
    ok = light_index[y] + eye_index[z] + 1 <= max_depth
    return y[ok], z[ok]


def pair_layout(rng: np.random.Generator, lanes: int):
    """The arguments of join_pairs for ``lanes`` lanes of random subpaths (some lanes without pairs)."""
    light_length, eye_length = rng.integers(0, 7, lanes), rng.integers(0, 7, lanes)
    light_index = np.concatenate([np.arange(n) for n in light_length]).astype(np.int64)
    eye_index = np.concatenate([np.arange(n) for n in eye_length]).astype(np.int64)
    light_lane, eye_lane = np.repeat(np.arange(lanes), light_length), np.repeat(np.arange(lanes), eye_length)
    cy = np.flatnonzero((light_index >= 1) & (rng.random(light_index.size) < 0.8))   # joinable vertices
    cz = np.flatnonzero((eye_index >= 1) & (rng.random(eye_index.size) < 0.8))
    ny, nz = np.bincount(light_lane[cy], minlength=lanes), np.bincount(eye_lane[cz], minlength=lanes)
    pair_start = np.concatenate([[0], np.cumsum(ny * nz)])
    y_start, z_start = np.concatenate([[0], np.cumsum(ny)[:-1]]), np.concatenate([[0], np.cumsum(nz)[:-1]])
    return [pair_start, nz, y_start, z_start, cy, cz, light_index, eye_index]


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("max_depth", [3, 6, 100])
def test_join_pairs_equal_numpy(seed, max_depth):
    """Every range of pairs: whole, from and to the middle of a lane, within one lane, empty; a depth limit that
    leaves out some pairs, and one that keeps all."""
    rng = np.random.default_rng(seed)
    layout = pair_layout(rng, 500)
    total = int(layout[0][-1])
    assert total > 1000
    cuts = sorted(rng.integers(0, total, 6).tolist())
    for begin, end in [(0, total), (cuts[0], cuts[3]), (cuts[1], cuts[2]), (cuts[4], cuts[4]), (cuts[5], total),
                       (0, 1), (total - 1, total)]:
        y, z = _native.join_pairs(*layout, begin, end, max_depth)
        y_ref, z_ref = pairs_numpy(*layout, begin, end, max_depth)
        same_bits(y, y_ref, f"y {begin}..{end}")
        same_bits(z, z_ref, f"z {begin}..{end}")
    kept = _native.join_pairs(*layout, 0, total, max_depth)[0].size
    assert (kept < total) == (max_depth < 11)   # subpath indices below 6: s + t - 1 <= 11


@pytest.mark.parametrize("position, value, error, match", [
    (0, np.array([0, 1]), ValueError, r"pair_start \(L \+ 1,\), nz, y_start and z_start \(L,\) must agree"),
    (2, np.zeros(3, np.int64), ValueError, "must agree"),
    (1, np.array([0, 0], np.int64), ValueError, "lane 0: pair_start and nz disagree"),
    (1, np.array([4, 2], np.int64), ValueError, "lane 0: pair_start and nz disagree"),
    (0, np.array([1, 6, 10]), ValueError, "pair_start must start at 0, got 1"),
    (2, np.array([2**63 - 1, 0]), IndexError, "lane 0: y_start or z_start is outside cy or cz"),
    (2, np.array([5, 0], np.int64), IndexError, "lane 0: y_start or z_start is outside cy or cz"),
    (5, np.array([0, 1, 9, 3], np.int64), IndexError, "cy or cz is outside the subpaths"),
    (4, np.array([-1, 1, 2], np.int64), IndexError, "lane 0: cy or cz is outside the subpaths"),
    (8, 11, ValueError, r"the pairs 11 \.\. 10 are not within 0 \.\. 10"),
    (9, 11, ValueError, r"the pairs 0 \.\. 11 are not within 0 \.\. 10"),
    (8, -1, ValueError, "are not within"),
    (0, np.array([0, 6, 10], np.int32), TypeError, "pair_start"),
])
def test_join_pairs_refuses_bad_arguments(position, value, error, match):
    # two lanes: 3 light x 2 camera vertices and 2 x 2
    args = [np.array([0, 6, 10]), np.array([2, 2]), np.array([0, 3]), np.array([0, 2]), np.arange(5),
            np.arange(4), np.ones(5, np.int64), np.ones(4, np.int64), 0, 10, 100]
    args[position] = value
    with pytest.raises(error, match=match):
        _native.join_pairs(*args)


# -- joins of made-up vertex pairs ---------------------------------------------------------------------------

@pytest.mark.parametrize("name, seed", [("cornell-box", 1), ("cornell-box-specular", 2)])
@pytest.mark.parametrize("occlusion", [True, False])
@pytest.mark.parametrize("technique", ["cosine", "uniform"])
def test_fused_joins_equal_numpy_on_extreme_pairs(name, seed, occlusion, technique, monkeypatch):
    """Through the shadow rays, and without them (every pair's value compared, the blocked ones too)."""
    sc = scene(name)
    rng = np.random.default_rng(seed)
    n = 8000
    light = made_up_side(sc, rng, n, 2)
    points = light.p.astype(np.float64)
    same = rng.random(n) < 0.02                                             # pairs at one point: d^2 = 0
    points[:, ~same] = rng.uniform(sc.mesh.vertices.min(axis=0), sc.mesh.vertices.max(axis=0), (n, 3)).T[:, ~same]
    eye = made_up_side(sc, rng, n, 3, points)
    if not occlusion:
        monkeypatch.setattr(connections, "segment_blocked", nothing_blocked)
    options = {"diffuse_sampling": technique}
    parts = {}
    for kernel in ("fused", "numpy"):
        fused, _ = join_kernel(sc, RGBColours, True, options, kernel)
        batch = Batch(sc, light, eye, None, RGBColours, options, 100, np.array([0, n]), join_kernel=fused)
        with np.errstate(all="ignore"):
            parts[kernel] = (_join(batch, light.at(np.arange(n)), eye.at(np.arange(n))), batch.rays, batch.nonfinite)
    (fused, rays_f, bad_f), (numpy, rays_n, bad_n) = parts["fused"], parts["numpy"]
    assert (rays_f, bad_f) == (rays_n, bad_n) and bad_f > 0 and fused.count > (1200 if not occlusion else 200)
    for density in ("qs_rev", "qs_minus_rev", "pt_rev", "pt_minus_rev"):   # the extremes reach every density
        values = getattr(fused, density)
        assert (values > 0).any() and (values == 0).any() and not np.isfinite(values).all(), density
    for field in ("value", "raster", "lane", "s", "t", "flags", *DENSITIES):
        same_bits(getattr(fused, field), getattr(numpy, field), field)


# -- what the kernel leaves to NumPy, and its refusals -------------------------------------------------------

def test_scenes_and_settings_the_kernel_does_not_serve_say_why():
    box = scene("cornell-box")
    cases = [
        (scene("veach-mis"), RGBColours, True, "fused", "material 'plate1' is conductor"),
        (box, SpectralColours(np.full((4, 1), 550.0), None, None), True, "fused", "spectral"),
        (box, RGBColours, False, "fused", "without MIS densities"),
        (box, RGBColours, True, "numpy", "kernel='numpy'"),
    ]
    for sc, colours, densities, kernel, reason in cases:
        fused, why = join_kernel(sc, colours, densities, {}, kernel)
        assert fused is None and reason in why
    for sc in (box, scene("cornell-box-thin-lens"), scene("cornell-box-point-light")):   # camera and lights: any
        assert join_kernel(sc, RGBColours, True, {}, "fused")[0] is not None
    plan = BDPT().plan(scene("cornell-box-thin-lens"))
    assert "light and camera vertices joined in one C pass (a fused kernel) in RGB, in NumPy when spectral" in plan
    assert "light vertices joined to the camera in NumPy (a camera other than a pinhole)" in plan
    assert "light and camera vertices joined in NumPy (kernel='numpy')" in BDPT(kernel="numpy").plan(box)


def kernel_args(k: int = 3):
    sc = scene("cornell-box")
    fused, _ = join_kernel(sc, RGBColours, True, {}, "fused")
    v = 4
    side = [np.ones((3, v), np.float32)] * 3 + [np.ones((3, v)), np.zeros(v, np.int64)] + [np.ones(v)] * 3
    return [*side, *side, np.arange(k, dtype=np.int64), np.arange(k, dtype=np.int64), fused.diffuse,
            fused.reflectance, 0]


@pytest.mark.parametrize("position, value, error, match", [
    (16, np.array([0, 4, 1]), IndexError, r"y\[1\] is not a vertex"),
    (16, np.array([-1, 0, 1]), IndexError, r"y\[0\] is not a vertex"),
    (17, np.array([0, 1, 9]), IndexError, r"z\[2\] is not a vertex"),
    (4, np.full(4, 99), IndexError, "pair 0 has no diffuse material"),
    (12, np.array([0, -1, 0, 0]), IndexError, "pair 1 has no diffuse material"),
    (0, np.ones((3, 5), np.float32), ValueError, "the light subpaths' .* must agree"),
    (11, np.ones((4, 4)), ValueError, "the camera subpaths' .* must agree"),
    (15, np.ones(5), ValueError, "the camera subpaths' .* must agree"),
    (17, np.arange(2), ValueError, "y and z .* must agree"),
    (19, np.ones((3, 1)), ValueError, "must agree"),
    (3, np.ones((3, 4), np.float32), TypeError, "beta"),
    (20, 2, ValueError, r"technique must be 0 \(cosine\) or 1 \(uniform\), got 2"),
])
def test_join_vertices_refuses_bad_arguments(position, value, error, match):
    args = kernel_args()
    args[position] = value
    with pytest.raises(error, match=match):
        _native.join_vertices(*args)


def test_join_vertices_refuses_a_material_that_is_not_diffuse():
    args = kernel_args()
    args[18] = np.zeros_like(args[18])
    with pytest.raises(IndexError, match="pair 0 has no diffuse material"):
        _native.join_vertices(*args)


def test_join_vertices_takes_no_pairs():
    out = _native.join_vertices(*kernel_args(0))
    assert out[0].shape == (3, 0) and all(a.shape == (0,) for a in out[1:])
