"""The fused vertex of the subpath walks (ext/pt_vertex.c through pt_fused.walk_vertex) against the NumPy code.

Light tracing and BDPT take their camera and light subpaths' vertices -- BSDF sample, roulette, next ray and the
reverse density of the direction sampled -- in one C pass where the scene allows (``kernel="fused"``);
``kernel="numpy"`` is the reference.  Compared bit for bit (as integers): whole renders under every roulette
policy (with the light subpaths' own), both diffuse techniques and on glass, with the kernel's calls counted;
then single vertices of camera walks (radiance) and light walks (importance), with and without densities, on
extreme inputs (throughputs over 300 decades and zero, infinite or NaN; grazing arrivals from both sides; NaN
directions; depths past the trapped depth or none deep enough for roulette; uniforms at 0, just below 1 and 1);
then the scenes and settings left to NumPy, and the refusals this use of the kernel adds.
"""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace import _native
from pathspace.estimators.base import Counters
from pathspace.estimators.bdpt import BDPT
from pathspace.estimators.control import RenderControl
from pathspace.estimators.lt import LightTracer
from pathspace.estimators.pt_fused import walk_vertex
from pathspace.estimators.subpaths import (CAMERA, CAMERA_VERTEX, LIGHT, LIGHT_VERTEX, SubpathSettings, _Growth,
                                           _Recorder, _walk_lanes)
from pathspace.estimators.walk import Dimensions, Walk
from pathspace.roulette import TRAPPED_DEPTH, RussianRoulette
from pathspace.sampler import ReplaySampler
from pathspace.spectra import RGBColours, SpectralColours
from conftest import count_lanes, extreme, extreme_arrivals, same_bits
from conftest import repository_scene as scene


@pytest.fixture
def kernel_calls(monkeypatch):
    """The number of lanes the fused vertex took so far (a list of one count)."""
    return count_lanes(monkeypatch, "pt_vertex", 19)


CONFIGS = {
    "default": {},
    "rr-throughput": {"rr": "throughput", "rr_depth": 2},
    "rr-fixed-light-throughput": {"rr": "fixed", "rr_probability": 0.3, "light_rr": "throughput", "light_rr_cap": 0.9},
    "rr-off": {"rr": "off", "max_depth": 7},
    "uniform-diffuse": {"diffuse_sampling": "uniform", "rr_depth": 3},
}


@pytest.mark.parametrize("estimator", ["lt", "bdpt"])
@pytest.mark.parametrize("config", CONFIGS)
@pytest.mark.parametrize("name", ["cornell-box", "cornell-box-specular"])
def test_fused_walks_render_what_numpy_renders(name, config, estimator, kernel_calls):
    sc = scene(name)
    fused = ps.render(sc, estimator, spp=2, seed=5, threads=1, **CONFIGS[config])
    taken = kernel_calls[0]
    assert taken > 0
    numpy = ps.render(sc, estimator, spp=2, seed=5, threads=1, kernel="numpy", **CONFIGS[config])
    assert kernel_calls[0] == taken
    assert "subpath vertices in one C pass (a fused kernel) in RGB, in NumPy when spectral" in fused.stats["plan"]
    assert fused.stats["rays"] == numpy.stats["rays"]
    assert fused.stats["longest_subpath"] == numpy.stats["longest_subpath"]
    same_bits(fused.image, numpy.image)


@pytest.mark.parametrize("name", ["caustic-glass", "pool", "furnace"])
def test_fused_walks_render_what_numpy_renders_through_glass(name, kernel_calls):
    sc = scene(name, (16, 16))
    for estimator in ("lt", "bdpt"):
        fused = ps.render(sc, estimator, spp=2, seed=5, threads=1, rr="throughput")
        same_bits(fused.image, ps.render(sc, estimator, spp=2, seed=5, threads=1, rr="throughput",
                                         kernel="numpy").image, estimator)
    assert kernel_calls[0] > 0


# -- single vertices on extreme inputs -----------------------------------------------------------------------

def extreme_growth(sc, kernel: str, transport: str, densities: bool, roulette: RussianRoulette, seed: int,
                   deep: bool = True, technique: str = "cosine", n: int = 6000):
    """A subpath walk of n lanes that have just arrived on random triangles of ``sc`` (see
    test_pt_vertex_kernel.extreme_walk): arrivals from both sides, grazing and along NaN directions; throughputs
    over 300 decades and some zero, negative zero, infinite or NaN; start scales over 6 decades and some 0 or
    infinite; depths from 1 to past the trapped depth (or all below rr_depth unless ``deep``); the uniforms of its
    next vertex, some 0, just below 1 or 1.  Returns (the growth, the arrival)."""
    rng = np.random.default_rng(seed)
    prim, b1, b2, normal, direction = extreme_arrivals(sc.mesh, rng, n)
    dims = CAMERA_VERTEX if transport == "radiance" else LIGHT_VERTEX
    u = rng.random((n, dims.size))
    for value in (0.0, np.nextafter(1.0, 0.0), 1.0):
        u[rng.random((n, dims.size)) < 0.02] = value
    beta = extreme(rng, n, 3, share=0.02)
    scale = 10.0 ** rng.uniform(-3, 3, n)
    scale[rng.random(n) < 0.02], scale[rng.random(n) < 0.02] = 0.0, np.inf
    depth = rng.integers(1, TRAPPED_DEPTH + 40, n) if deep else rng.integers(1, roulette.start_depth, n)
    extra = {"rr_scale": scale} if transport == "importance" and roulette.policy == "throughput" else {}
    lanes = _walk_lanes(n, densities, origin=np.zeros((3, n), np.float32), direction=direction, beta=beta,
                        pdf=10.0 ** rng.uniform(-100, 100, n), prev_n=normal.astype(np.float32),
                        prev_infinite=rng.random(n) < 0.05, **extra)
    lanes.depth, lanes.delta = depth.astype(np.int32), rng.random(n) < 0.3
    if densities:
        lanes.q = rng.random(n)
    walk = Walk(sc, lanes, ReplaySampler(u), roulette, dims, transport)
    if "eta_scale" in lanes.fields:
        lanes.eta_scale = scale
    settings = SubpathSettings(sc, RGBColours, {"diffuse_sampling": technique}, roulette, roulette,
                               TRAPPED_DEPTH + 100, Counters(), RenderControl(), densities, kernel)
    recorder = _Recorder(densities=densities)
    first = recorder.add(np.arange(n), 0, CAMERA if transport == "radiance" else LIGHT, p=np.zeros((3, n), np.float32),
                         n=normal.astype(np.float32), beta=np.ones((3, n)), fwd=np.ones(n),
                         u=np.zeros((dims.sizes["connect"], n)))
    opposite = RussianRoulette("fixed", 1, 0.25)
    growth = _Growth(settings, walk, opposite, recorder, first, n)
    return growth, walk.arrive(prim, b1, b2, rng.uniform(0.1, 2.0, n).astype(np.float32))


ROULETTES = {"albedo": RussianRoulette("albedo", 1), "fixed": RussianRoulette("fixed", 2, 0.3),
             "throughput": RussianRoulette("throughput", 1, cap=0.95), "off": RussianRoulette("off"),
             "throughput-late": RussianRoulette("throughput", 4)}


@pytest.mark.parametrize("transport", ["radiance", "importance"])
@pytest.mark.parametrize("densities", [True, False])
@pytest.mark.parametrize("policy, deep, technique", [(policy, True, "cosine") for policy in ROULETTES]
                         + [("throughput-late", False, "cosine"), ("albedo", True, "uniform")])
def test_fused_walk_vertex_equals_numpy_on_extreme_inputs(transport, densities, policy, deep, technique):
    sc = scene("cornell-box-specular")
    runs = {}
    for kernel in ("fused", "numpy"):
        growth, arrival = extreme_growth(sc, kernel, transport, densities, ROULETTES[policy], seed=13, deep=deep,
                                         technique=technique)
        assert (growth.fused is not None) == (kernel == "fused")
        with np.errstate(all="ignore"):
            assert growth._vertex(arrival)
        runs[kernel] = growth
    fused, numpy = runs["fused"], runs["numpy"]
    lanes_f, lanes_n = fused.walk.lanes, numpy.walk.lanes
    assert lanes_f.fields == lanes_n.fields
    for name in lanes_f.fields:
        same_bits(getattr(lanes_f, name), getattr(lanes_n, name), name)
    assert (lanes_f.size < 6000) == (deep and policy != "off") and lanes_f.size > 0
    records_f, records_n = fused.recorder.records, numpy.recorder.records
    assert len(records_f) == len(records_n) == 2
    for record_f, record_n in zip(records_f, records_n):
        assert record_f.keys() == record_n.keys()
        for name in record_f:
            same_bits(record_f[name], record_n[name], name)
    if densities:   # the reverse densities of the vertices 0, from the directions sampled
        rev = records_f[0]["rev"]
        assert (rev > 0).any() and (rev == 0).any()


# -- what the kernel leaves to NumPy, and its refusals -------------------------------------------------------

def test_scenes_and_settings_the_walk_kernel_does_not_serve_say_why():
    box = scene("cornell-box")
    roulette = RussianRoulette("albedo", 1)
    cases = [
        (scene("veach-mis"), RGBColours, CAMERA_VERTEX, "fused", "material 'plate1' is conductor"),
        (box, SpectralColours(np.full((4, 1), 550.0), None, None), CAMERA_VERTEX, "fused", "spectral"),
        (box, RGBColours, Dimensions(roulette=1, bsdf=3), "fused", "laid out differently"),
        (box, RGBColours, Dimensions(bsdf=2, roulette=1), "fused", "laid out differently"),
        (box, RGBColours, CAMERA_VERTEX, "numpy", "kernel='numpy'"),
    ]
    for sc, colours, dims, kernel, reason in cases:
        fused, why = walk_vertex(sc, colours, roulette, {}, dims, "radiance", True, kernel)
        assert fused is None and reason in why
    for dims, transport in ((CAMERA_VERTEX, "radiance"), (LIGHT_VERTEX, "importance"),
                            (Dimensions(connect=2, bsdf=3, roulette=1), "importance")):
        fused, _ = walk_vertex(box, RGBColours, roulette, {}, dims, transport, False, "fused")
        assert fused.walk == (dims.sizes.get("connect", 0) if list(dims.sizes)[0] == "connect" else 0,
                              int(transport == "importance"), 0)
    assert "subpath vertices in NumPy (material 'plate1' is conductor)" in LightTracer().plan(scene("veach-mis"))
    assert "subpath vertices in NumPy (kernel='numpy')" in BDPT(kernel="numpy").plan(box)


def test_pt_vertex_refuses_importance_throughput_roulette_without_its_scale():
    sc = scene("cornell-box")
    fused, _ = walk_vertex(sc, RGBColours, RussianRoulette("throughput", 1), {}, LIGHT_VERTEX, "importance", True,
                           "fused")
    n = 4
    p = np.zeros((3, n), np.float32)
    lanes = [p, p, np.zeros(n, np.float32), np.ones(n, np.float32), p, np.zeros(n, np.int32), np.ones((3, n)),
             None, None, np.ones(n, np.int32), np.full((6, n), 0.5), np.ones(n, np.float32), np.zeros(n, np.float32)]
    args = [*fused.materials, *fused.lights, *lanes, *fused.options, *fused.walk]
    with pytest.raises(ValueError, match="importance reads rr_scale, which is None"):
        _native.pt_vertex(*args)
    args[17] = args[18] = np.ones(n)
    with pytest.raises(ValueError, match="eta_scale is for radiance, rr_scale for importance"):
        _native.pt_vertex(*args)
    args[17] = None
    out = _native.pt_vertex(*args)
    assert out[12] is None and out[13].shape == (n,) and out[14] == 0
