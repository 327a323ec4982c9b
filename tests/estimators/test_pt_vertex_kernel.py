"""The path tracer's fused vertex (ext/pt_vertex.c) against the NumPy code it stands for.

``PathTracer(kernel="fused")`` takes next-event estimation, BSDF sampling and roulette in one C pass where
the scene allows (:mod:`pathspace.estimators.pt_fused`); ``kernel="numpy"`` is the reference.  Compared bit
for bit (as integers: -0.0 is not 0.0): whole renders under every light strategy, heuristic, diffuse
technique and roulette policy the kernel serves, on scenes with diffuse, mirror and glass surfaces, with the
kernel's calls counted; then single vertices on extreme inputs (throughputs over 300 decades and zero,
infinite or NaN, eta scales of 0 and infinity, grazing arrivals from both sides, NaN directions, paths past
the trapped depth or none deep enough for roulette, uniforms at 0, just below 1 and at 1); then the scenes and
settings left to NumPy, a resumed render across the two kernels, and the kernel's refusals.
"""
from __future__ import annotations

import copy

import numpy as np
import pytest

import pathspace as ps
from pathspace import _native, warp
from pathspace.bsdfs import Dielectric, Diffuse, MaterialTable, Mirror
from pathspace.estimators.base import Counters
from pathspace.estimators.pt import PathTracer
from pathspace.estimators.pt_fused import MODELS, fused_vertex
from pathspace.estimators.walk import Walk
from pathspace.estimators.wavefront import Lanes
from pathspace.resume import render_identity
from pathspace.roulette import TRAPPED_DEPTH
from pathspace.sampler import ReplaySampler
from pathspace.spectra import RGBMode, SpectralMode

from conftest import count_lanes, extreme, extreme_arrivals, same_bits
from conftest import repository_scene as scene

CONFIGS = {
    "default": {},
    "nee": {"light_sampling": "nee"},
    "bsdf-only": {"light_sampling": "none"},
    "balance": {"mis": "balance"},
    "uniform-mis": {"mis": "uniform"},
    "power-3": {"mis_beta": 3.0},
    "uniform-diffuse": {"diffuse_sampling": "uniform"},
    "uniform-selection": {"light_selection": "uniform"},
    "rr-fixed": {"rr": "fixed", "rr_probability": 0.3, "rr_depth": 2},
    "rr-albedo": {"rr": "albedo", "rr_depth": 1},
    "rr-off": {"rr": "off", "max_depth": 9},
    "rr-cap": {"rr_cap": 0.9, "rr_depth": 1},
}


@pytest.fixture
def kernel_calls(monkeypatch):
    """The number of lanes the fused kernel took so far (a list of one count)."""
    return count_lanes(monkeypatch, "pt_vertex", 19)


def render(sc, **params):
    return ps.render(sc, "pt", spp=2, seed=5, threads=1, **params)


def fused_and_numpy(sc, kernel_calls, **params):
    """The renders of ``sc`` through the fused kernel (which must run) and through NumPy (which must not)."""
    fused = render(sc, kernel="fused", **params)
    assert kernel_calls[0] > 0
    taken = kernel_calls[0]
    numpy = render(sc, kernel="numpy", **params)
    assert kernel_calls[0] == taken
    return fused, numpy


@pytest.mark.parametrize("config", CONFIGS)
@pytest.mark.parametrize("name", ["cornell-box", "cornell-box-specular"])
def test_fused_renders_equal_numpy_renders(name, config, kernel_calls):
    fused, numpy = fused_and_numpy(scene(name), kernel_calls, **CONFIGS[config])
    assert any("one C pass" in line for line in fused.stats["plan"])
    assert fused.stats["rays"] == numpy.stats["rays"]
    assert fused.stats["longest_subpath"] == numpy.stats["longest_subpath"]
    for name in ("scaled_mean", "scaled_m2", "exponent"):
        same_bits(getattr(fused.film.moments, name), getattr(numpy.film.moments, name), name)


@pytest.mark.parametrize("name", ["caustic-glass", "pool", "furnace"])
def test_fused_renders_equal_numpy_renders_through_glass(name, kernel_calls):
    fused, numpy = fused_and_numpy(scene(name, (16, 16)), kernel_calls)
    same_bits(fused.film.moments.scaled_mean, numpy.film.moments.scaled_mean)


# -- single vertices on extreme inputs -----------------------------------------------------------------------

def extreme_walk(sc, tracer: PathTracer, seed: int, n: int = 6000, deep: bool = True):
    """A walk of n lanes that have just arrived on random triangles of ``sc``: arrivals from both sides, at
    grazing angles and along NaN directions; throughputs over 300 decades, and some zero, negative zero,
    infinite or NaN; eta scales over 6 decades, and some 0 or infinite; depths from 1 to past the trapped
    depth (or all below ``rr_depth`` unless ``deep``); and the uniforms of its next vertex, some 0, just
    below 1 or 1."""
    rng = np.random.default_rng(seed)
    prim, b1, b2, _, direction = extreme_arrivals(sc.mesh, rng, n)
    u = rng.random((n, 7))
    for value in (0.0, np.nextafter(1.0, 0.0), 1.0):
        u[rng.random((n, 7)) < 0.02] = value
    beta = extreme(rng, n, 3, share=0.02)
    eta_scale = 10.0 ** rng.uniform(-3, 3, n)
    eta_scale[rng.random(n) < 0.02], eta_scale[rng.random(n) < 0.02] = 0.0, np.inf
    start = tracer.roulette.start_depth
    depth = rng.integers(1, TRAPPED_DEPTH + 40, n) if deep else rng.integers(1, start, n)
    camera_dims, vertex_dims = tracer.dimensions(RGBMode())
    lanes = Lanes(("ticket", "depth", "origin", "direction", "beta", "radiance", "pdf", "delta", "eta_scale"),
                  ticket=np.zeros(n, np.int64), depth=depth.astype(np.int32), origin=np.zeros((3, n), np.float32),
                  direction=direction, beta=beta, radiance=rng.random((3, n)), pdf=10.0 ** rng.uniform(-100, 100, n),
                  delta=rng.random(n) < 0.3, eta_scale=eta_scale)
    walk = Walk(sc, lanes, ReplaySampler(u), tracer.roulette, vertex_dims)
    return walk, walk.arrive(prim, b1, b2, rng.uniform(0.1, 2.0, n).astype(np.float32))


@pytest.mark.parametrize("config, deep", [(config, True) for config in ("default", "nee", "bsdf-only",
                                                                        "uniform-diffuse", "rr-fixed", "rr-albedo",
                                                                        "rr-off", "rr-cap")]
                         + [("default", False), ("rr-fixed", False)])
def test_fused_vertex_equals_numpy_on_extreme_inputs(config, deep):
    sc = scene("cornell-box-specular")
    lanes = {}
    for kernel in ("fused", "numpy"):
        tracer = PathTracer(kernel=kernel, **CONFIGS[config])
        walk, arrival = extreme_walk(sc, tracer, seed=11, deep=deep)
        bounce = tracer._bounce_context(sc, RGBMode(), Counters())
        walk.lanes.ticket = bounce.book.open("paths", walk.size)
        assert (bounce.fused is not None) == (kernel == "fused")
        with np.errstate(all="ignore"):
            tracer._scatter(walk, arrival, bounce)
        lanes[kernel] = (walk.lanes, walk.rays, bounce.book)
    fused, numpy = lanes["fused"], lanes["numpy"]
    assert fused[1] == numpy[1]
    assert fused[1] > 0 or config == "bsdf-only"
    for name in fused[0].fields:
        same_bits(getattr(fused[0], name), getattr(numpy[0], name), name)
    roulette = deep and config != "rr-off"
    assert (fused[0].size < 6000) == roulette   # roulette ended paths, which handed their radiance over
    same_bits(fused[2].values[0], numpy[2].values[0])


# -- what the kernel leaves to NumPy -------------------------------------------------------------------------

class Lambert(Diffuse):
    """A model of the user's own that happens to derive from the kernel's diffuse model."""


def test_scenes_and_settings_the_kernel_does_not_serve_say_why():
    tracer = PathTracer()
    box = scene("cornell-box")
    own = copy.copy(box)
    own.materials = MaterialTable(box.materials.names, [Lambert(m.reflectance) for m in box.materials.materials])
    cases = [
        (scene("veach-mis"), RGBMode(), "mis", "material 'plate1' is conductor"),
        (own, RGBMode(), "mis", "material 'white' is diffuse"),
        (scene("cornell-box-point-light"), RGBMode(), "mis", "lights other than area lights"),
        (box, SpectralMode(), "mis", "spectral"),
        (box, RGBMode(), "mixture", "mixture"),
    ]
    for sc, mode, strategy, reason in cases:
        fused, why = fused_vertex(tracer, sc, mode, strategy, 2)
        assert fused is None and reason in why
    fused, why = fused_vertex(PathTracer(light_measure="solid_angle"), box, RGBMode(), "mis", 2)
    assert fused is None and "solid_angle" in why
    assert fused_vertex(PathTracer(kernel="numpy"), box, RGBMode(), "mis", 2)[0] is None
    assert fused_vertex(PathTracer(rr_depth=2 ** 40), box, RGBMode(), "mis", 2)[0] is not None
    assert any("in NumPy (material 'plate1' is conductor)" in line for line in tracer.plan(scene("veach-mis")))


def test_pt_refuses_an_unknown_kernel():
    with pytest.raises(ValueError, match="kernel"):
        PathTracer(kernel="cuda")


def test_the_kernel_is_not_part_of_a_renders_identity():
    """Both kernels make the same image: a render saved with one resumes with the other."""
    box = scene("cornell-box")

    def identity(tracer):
        return render_identity(box, tracer, RGBMode(), seed=1, first_pass=0, spp=4, time=None)

    assert identity(PathTracer(kernel="numpy")) == identity(PathTracer(kernel="fused"))
    assert identity(PathTracer(mis="balance")) != identity(PathTracer())
    assert PathTracer(kernel="numpy").params["kernel"] == "numpy"


def test_the_constants_shared_with_c_agree():
    assert (_native.INV_PI, _native.INV_TWO_PI) == (warp.INV_PI, warp.INV_TWO_PI)
    assert set(MODELS) == {Diffuse, Mirror, Dielectric}
    assert [model.kind for model in sorted(MODELS, key=MODELS.get)] == list(_native.PT_VERTEX_KINDS)


def kernel_args(n: int = 4):
    sc = scene("cornell-box")
    tracer = PathTracer()
    fused, _ = fused_vertex(tracer, sc, RGBMode(), "mis", 2)
    p = np.zeros((3, n), np.float32)
    lanes = [p, p, np.zeros(n, np.float32), np.ones(n, np.float32), p, np.zeros(n, np.int32), np.ones((3, n)),
             np.ones(n), None, np.ones(n, np.int32), np.full((7, n), 0.5), np.ones(n, np.float32),
             np.zeros(n, np.float32)]
    return [*fused.materials, *fused.lights, *lanes, *fused.options, *fused.walk]


@pytest.mark.parametrize("position, value, error, match", [
    (15, np.full(4, 7, np.int32), IndexError, r"material\[0\] is not a material"),
    (15, np.full(4, -1, np.int32), IndexError, r"material\[0\] is not a material"),
    (20, np.full((6, 4), 0.5), ValueError, r"u must have shape \(R, N\) with N = 4 .* rows 3 \.\. 6"),
    (20, np.full((7, 5), 0.5), ValueError, r"u must have shape \(R, N\) with N = 4"),
    (31, 0, ValueError, r"u must have shape .* after the light sample's \(rows 0 \.\. 2\) if taken"),
    (31, -1, ValueError, "bsdf_row >= 0"),
    (32, 2, ValueError, "importance and reverse 0 or 1"),
    (33, -1, ValueError, "importance and reverse 0 or 1"),
    (32, 1, ValueError, "no light samples when transporting importance"),
    (18, np.ones(4), ValueError, "eta_scale is for radiance, rr_scale for importance"),
    (10, np.zeros((3, 5), np.float32), ValueError, r"p must have shape \(3, N\) with N = 4"),
    (10, np.zeros((4, 3), np.float32).T, ValueError, "p must be C-contiguous"),
    (17, None, ValueError, "eta_scale"),
    (4, None, ValueError, "light tables"),
    (7, np.ones(3), ValueError, r"table \(13, E\)"),
    (9, np.ones((3, 3)), ValueError, r"radiance \(3, E\)"),
    (1, np.ones((3, 4)), ValueError, r"reflectance \(3, M\)"),
    (0, np.full(3, 5, np.int8), ValueError, "not a material kind"),
    (16, np.ones((3, 4), np.float32), TypeError, "beta"),
    (23, 2, ValueError, "diffuse technique"),
    (24, 4, ValueError, "heuristic"),
    (24, -2, ValueError, "heuristic"),
    (25, 9, ValueError, "roulette policy"),
])
def test_pt_vertex_refuses_bad_arguments(position, value, error, match):
    args = kernel_args()
    args[position] = value
    with pytest.raises(error, match=match):
        _native.pt_vertex(*args)


def test_pt_vertex_takes_valid_arguments_and_no_lanes():
    out = _native.pt_vertex(*kernel_args())
    assert len(out) == 15 and out[0].shape == (3, 4) and out[13] is None and out[14] == 4
    assert out[7].dtype == bool
    out = _native.pt_vertex(*kernel_args(0))
    assert out[0].shape == (3, 0) and out[14] == 0


@pytest.mark.parametrize("kernel, args", [
    ("scatter_step", [np.ones((5, 3)), np.ones((5, 3)), None, np.zeros(3)] + [np.zeros((3, 3), np.float32)] * 2
     + [np.zeros(3, np.float32), np.zeros((3, 3), np.float32)]),
    ("next_event_value", [np.ones((5, 3))] * 3 + [np.ones(3)] * 2 + [np.ones(3, bool), None, 2, 2.0]),
])
def test_per_lane_kernels_refuse_more_than_four_channels(kernel, args):
    with pytest.raises(ValueError, match="1 <= C <= 4"):
        getattr(_native, kernel)(*args)
