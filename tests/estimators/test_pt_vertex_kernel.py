"""The path tracer's fused vertex (ext/pt_vertex.c) against the NumPy code it stands for.

``PathTracer(kernel="fused")`` takes next-event estimation, BSDF sampling and roulette in one C pass where
the scene allows (:mod:`pathspace.estimators.pt_fused`); ``kernel="numpy"`` is the reference.  Compared bit
for bit: whole renders under every light strategy, heuristic, diffuse technique and roulette policy the kernel
serves, on scenes with diffuse, mirror and glass surfaces; then single vertices on extreme inputs
(throughputs over 300 decades, grazing arrivals from both sides, paths past the trapped depth, uniforms at 0
and just below 1); then the scenes and settings left to NumPy, and the kernel's refusals.
"""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace import _native
from pathspace.estimators.pt import PathTracer
from pathspace.estimators.pt_fused import fused_vertex
from pathspace.estimators.walk import Walk
from pathspace.estimators.wavefront import Lanes
from pathspace.roulette import TRAPPED_DEPTH
from pathspace.sampler import ReplaySampler
from pathspace.spectra import RGBMode

from conftest import ROOT

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


def scene(name: str, resolution=(24, 24)):
    return ps.load_scene(ROOT / "scenes" / name / "scene.toml", **{"camera.resolution": list(resolution)})


def render(sc, **params):
    return ps.render(sc, "pt", spp=2, seed=5, threads=1, **params)


@pytest.mark.parametrize("config", CONFIGS)
@pytest.mark.parametrize("name", ["cornell-box", "cornell-box-specular"])
def test_fused_renders_equal_numpy_renders(name, config):
    sc = scene(name)
    fused, numpy = render(sc, kernel="fused", **CONFIGS[config]), render(sc, kernel="numpy", **CONFIGS[config])
    assert any("one C pass" in line for line in fused.stats["plan"])
    assert fused.stats["rays"] == numpy.stats["rays"]
    np.testing.assert_array_equal(fused.image, numpy.image)
    assert np.array_equal(fused.film.sum, numpy.film.sum) and np.array_equal(fused.film.sum_sq, numpy.film.sum_sq)


@pytest.mark.parametrize("name", ["caustic-glass", "pool", "furnace"])
def test_fused_renders_equal_numpy_renders_through_glass(name):
    sc = scene(name, (16, 16))
    np.testing.assert_array_equal(render(sc, kernel="fused").image, render(sc, kernel="numpy").image)


# -- single vertices on extreme inputs -----------------------------------------------------------------------

def extreme_walk(sc, tracer: PathTracer, seed: int, n: int = 6000):
    """A walk of n lanes that have just arrived on random triangles of ``sc``: arrivals from both sides and at
    grazing angles, throughputs over 300 decades, eta scales over 6, depths from 1 to past the trapped depth,
    and the uniforms of its next vertex (some 0, some just below 1)."""
    rng = np.random.default_rng(seed)
    mesh = sc.mesh
    prim = rng.integers(0, mesh.material.size, n).astype(np.int32)
    b1, b2 = rng.random(n), rng.random(n)
    flip = b1 + b2 > 1
    b1[flip], b2[flip] = 1 - b1[flip], 1 - b2[flip]
    b1, b2 = b1.astype(np.float32), b2.astype(np.float32)
    _, normal, _ = mesh.hit_geometry(prim, b1, b2)
    tangent = np.cross(normal.T, rng.normal(size=(n, 3))).T
    tangent /= np.linalg.norm(tangent, axis=0)
    height = np.where(rng.random(n) < 0.3, 10.0 ** rng.uniform(-9, -2, n), rng.uniform(0.0, 1.0, n))
    side = np.where(rng.random(n) < 0.5, 1.0, -1.0)
    direction = -(side * height * normal + np.sqrt(1 - height ** 2) * tangent)   # toward the surface
    direction = (direction / np.linalg.norm(direction, axis=0)).astype(np.float32)
    u = rng.random((n, 7))
    u[rng.random((n, 7)) < 0.02] = 0.0
    u[rng.random((n, 7)) < 0.02] = np.nextafter(1.0, 0.0)
    camera_dims, vertex_dims = tracer.dimensions(RGBMode())
    lanes = Lanes(("ticket", "depth", "origin", "direction", "beta", "radiance", "pdf", "delta", "eta_scale"),
                  ticket=np.zeros(n, np.int64), depth=rng.integers(1, TRAPPED_DEPTH + 40, n).astype(np.int32),
                  origin=np.zeros((3, n), np.float32), direction=direction,
                  beta=10.0 ** rng.uniform(-150, 150, (3, n)), radiance=rng.random((3, n)),
                  pdf=10.0 ** rng.uniform(-100, 100, n), delta=rng.random(n) < 0.3,
                  eta_scale=10.0 ** rng.uniform(-3, 3, n))
    walk = Walk(sc, lanes, ReplaySampler(u), tracer.roulette, vertex_dims)
    return walk, walk.arrive(prim, b1, b2, rng.uniform(0.1, 2.0, n).astype(np.float32))


@pytest.mark.parametrize("config", ["default", "nee", "bsdf-only", "uniform-diffuse", "rr-fixed", "rr-albedo",
                                    "rr-off", "rr-cap"])
def test_fused_vertex_equals_numpy_on_extreme_inputs(config):
    sc = scene("cornell-box-specular")
    lanes = {}
    for kernel in ("fused", "numpy"):
        tracer = PathTracer(kernel=kernel, **CONFIGS[config])
        walk, arrival = extreme_walk(sc, tracer, seed=11)
        bounce = tracer._bounce_context(sc, RGBMode(), ps.estimators.base.Counters())
        walk.lanes.ticket = bounce.book.open("paths", walk.size)
        assert (bounce.fused is not None) == (kernel == "fused")
        tracer._scatter(walk, arrival, bounce)
        lanes[kernel] = (walk.lanes, walk.rays, bounce.book)
    fused, numpy = lanes["fused"], lanes["numpy"]
    assert fused[1] == numpy[1]
    for name in fused[0].fields:
        np.testing.assert_array_equal(getattr(fused[0], name), getattr(numpy[0], name), err_msg=name)
    assert fused[1] > 0 or config == "bsdf-only"
    assert (fused[0].size < 6000) == (config != "rr-off")   # roulette ended paths, which handed their radiance over
    np.testing.assert_array_equal(fused[2].values[0], numpy[2].values[0])


# -- what the kernel leaves to NumPy -------------------------------------------------------------------------

def test_scenes_and_settings_the_kernel_does_not_serve_say_why():
    tracer = PathTracer()
    cases = [
        (scene("veach-mis"), RGBMode(), "mis", "is conductor"),
        (scene("cornell-box-point-light"), RGBMode(), "mis", "lights other than area lights"),
        (scene("cornell-box"), ps.spectra.SpectralMode(), "mis", "spectral"),
        (scene("cornell-box"), RGBMode(), "mixture", "mixture"),
    ]
    for sc, mode, strategy, reason in cases:
        fused, why = fused_vertex(tracer, sc, mode, strategy, 2)
        assert fused is None and reason in why
    fused, why = fused_vertex(PathTracer(light_measure="solid_angle"), scene("cornell-box"), RGBMode(), "mis", 2)
    assert fused is None and "solid_angle" in why
    assert fused_vertex(PathTracer(kernel="numpy"), scene("cornell-box"), RGBMode(), "mis", 2)[0] is None
    assert any("in NumPy (material 'plate1' is conductor)" in line for line in tracer.plan(scene("veach-mis")))


def test_pt_refuses_an_unknown_kernel():
    with pytest.raises(ValueError, match="kernel"):
        PathTracer(kernel="cuda")


def kernel_args(n: int = 4):
    sc = scene("cornell-box")
    tracer = PathTracer()
    fused, _ = fused_vertex(tracer, sc, RGBMode(), "mis", 2)
    p = np.zeros((3, n), np.float32)
    lanes = [p, p, np.zeros(n, np.float32), np.ones(n, np.float32), p, np.zeros(n, np.int32), np.ones((3, n)),
             np.ones(n), np.ones(n, np.int32), np.full((7, n), 0.5), np.ones(n, np.float32), np.zeros(n, np.float32)]
    return [*fused.materials, *fused.lights, *lanes, *fused.options]


@pytest.mark.parametrize("position, value, error, match", [
    (15, np.full(4, 7, np.int32), IndexError, r"material\[0\] is not a material"),
    (15, np.full(4, -1, np.int32), IndexError, r"material\[0\] is not a material"),
    (19, np.full((6, 4), 0.5), ValueError, r"u must have shape \(7, N\)"),
    (10, np.zeros((3, 5), np.float32), ValueError, r"p must have shape \(3, N\) with N = 4"),
    (17, None, ValueError, "eta_scale"),
    (4, None, ValueError, "light tables"),
    (0, np.full(3, 5, np.int8), ValueError, "not a material kind"),
    (16, np.ones((3, 4), np.float32), TypeError, "beta"),
    (24, 9, ValueError, "roulette policy"),
])
def test_pt_vertex_refuses_bad_arguments(position, value, error, match):
    args = kernel_args()
    args[position] = value
    with pytest.raises(error, match=match):
        _native.pt_vertex(*args)


def test_pt_vertex_takes_valid_arguments():
    out = _native.pt_vertex(*kernel_args())
    assert len(out) == 14 and out[0].shape == (3, 4) and out[13] == 4
    assert out[7].dtype == bool
