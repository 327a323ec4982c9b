"""The fused connections of light vertices to the camera (ext/lens_connect.c) against the NumPy code they stand for.

``LightTracer(kernel="fused")`` and ``BDPT(kernel="fused")`` join light vertices to a pinhole camera in one C
pass where the scene allows (:mod:`pathspace.estimators.lens_fused`); ``kernel="numpy"`` is the reference.
Compared bit for bit (as integers): whole light-tracing renders on scenes with diffuse, mirror and glass surfaces
under several depths and roulette policies, with the kernel's calls counted (BDPT's renders are compared in
test_join_kernel.py); then the connections of made-up subpaths with extreme vertices (throughputs over 300
decades and zero, infinite or NaN; vertices behind, beside and right at the camera; surfaces seen from both
sides and edge-on; no normal, NaN normals and directions; points on one- and two-sided lights, facing the camera
or not; densities and survival probabilities over 300 decades and zero, infinite or NaN), with and without MIS
densities, through the shadow rays and without them; then the scenes and settings left to NumPy, and the
kernel's refusals.
"""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace import _native
from pathspace.estimators import connections
from pathspace.estimators.connections import Batch, lens_samples
from pathspace.estimators.lens_fused import lens_kernel
from pathspace.estimators.lt import LightTracer
from pathspace.estimators.subpaths import FIELDS, LIGHT, SURFACE, Subpaths
from pathspace.spectra import RGBColours, SpectralColours
from conftest import count_lanes, extreme, extreme_normals_and_directions, nothing_blocked, same_bits
from conftest import repository_scene as scene


@pytest.fixture
def kernel_calls(monkeypatch):
    """The number of vertices the fused kernel joined so far (a list of one count)."""
    return count_lanes(monkeypatch, "lens_connect", 6)


CONFIGS = {
    "default": {},
    "short": {"max_depth": 3},
    "rr-fixed": {"rr": "fixed", "rr_probability": 0.3, "rr_depth": 2},
    "rr-albedo": {"rr": "albedo", "rr_depth": 1},
    "uniform-diffuse": {"diffuse_sampling": "uniform"},
}


@pytest.mark.parametrize("config", CONFIGS)
@pytest.mark.parametrize("name", ["cornell-box", "cornell-box-specular"])
def test_fused_light_tracing_equals_numpy(name, config, kernel_calls):
    sc = scene(name)
    fused = ps.render(sc, "lt", spp=2, seed=5, threads=1, kernel="fused", **CONFIGS[config])
    joined = kernel_calls[0]
    assert joined > 0
    numpy = ps.render(sc, "lt", spp=2, seed=5, threads=1, kernel="numpy", **CONFIGS[config])
    assert kernel_calls[0] == joined
    assert any("camera in one C pass" in line for line in fused.stats["plan"])
    assert fused.stats["rays"] == numpy.stats["rays"]
    for name in ("scaled_mean", "scaled_m2", "exponent"):
        same_bits(getattr(fused.film.moments, name), getattr(numpy.film.moments, name), name)
    same_bits(fused.image, numpy.image)


@pytest.mark.parametrize("name", ["caustic-glass", "pool", "furnace"])
def test_fused_light_tracing_equals_numpy_through_glass(name, kernel_calls):
    sc = scene(name, (16, 16))
    fused = ps.render(sc, "lt", spp=2, seed=5, threads=1)
    assert kernel_calls[0] > 0
    same_bits(fused.image, ps.render(sc, "lt", spp=2, seed=5, threads=1, kernel="numpy").image)


# -- connections of made-up subpaths ------------------------------------------------------------------------

def made_up_subpaths(sc, rng: np.random.Generator, n: int = 8000) -> Subpaths:
    """n one-vertex-per-lane subpaths of vertices in front of the camera: on surfaces (diffuse, mirror, glass;
    seen from both sides and edge-on) and on the lights (facing the camera or not), some right at the pinhole,
    behind it or beside the film, some with no normal or a NaN one or a NaN direction back; throughputs over 300
    decades and some zero, negative zero, infinite or NaN, and so their densities and survival probabilities."""
    camera = sc.camera
    depth = rng.uniform(0.5, 6.0, n)
    depth[rng.random(n) < 0.05] *= -1.0                                                # behind the pinhole
    across = rng.uniform(-1.2, 1.2, (2, n)) * depth * np.array(camera.tan_half)[:, None]   # some beside the film
    p = (camera.position[:, None] + camera.forward[:, None] * depth + camera.right[:, None] * across[0]
         + camera.image_up[:, None] * across[1])
    p[:, rng.random(n) < 0.03] = camera.position[:, None]                              # at the pinhole
    normal, wo = extreme_normals_and_directions(rng, n)
    beta = extreme(rng, n, 3)
    densities = {name: extreme(rng, n) for name in ("fwd", "rev", "g_prev", "q", "q_rev")}
    on_light = rng.random(n) < 0.3
    kind = np.where(on_light & (rng.random(n) < 0.5), LIGHT, SURFACE).astype(np.int8)
    materials = sc.materials
    material = rng.integers(0, len(materials), n)
    entity = np.where(on_light, rng.integers(0, sc.lights.area.count, n), -1)
    fields = dict.fromkeys(FIELDS)
    fields.update(lane=np.arange(n), index=rng.integers(0, 6, n), p=p.astype(np.float32),
                  n=normal.astype(np.float32), eps=np.full(n, 1e-5, np.float32), wo=wo.astype(np.float32),
                  beta=beta, delta=materials.delta.take(material) & (kind == SURFACE), kind=kind, material=material,
                  entity=entity, u=rng.random((2, n)), infinite=np.zeros(n, bool), **densities)
    return Subpaths(offset=np.arange(n + 1), terminated=np.zeros(n, bool), **fields)


@pytest.mark.parametrize("name, seed", [("cornell-box", 1), ("cornell-box-specular", 2)])
@pytest.mark.parametrize("occlusion", [True, False])
@pytest.mark.parametrize("densities, technique", [(False, "cosine"), (True, "cosine"), (True, "uniform")])
def test_fused_connections_equal_numpy_on_extreme_vertices(name, seed, occlusion, densities, technique, monkeypatch):
    """Through the shadow rays, and without them (every vertex's value compared, the blocked ones too); without
    densities (light tracing) and with them (BDPT), under both diffuse sampling techniques."""
    sc = scene(name)
    rng = np.random.default_rng(seed)
    light = made_up_subpaths(sc, rng)
    two_sided = sc.lights.area.two_sided
    two_sided[0] = True    # one two-sided emitting triangle, one one-sided
    assert two_sided.any() and not two_sided.all()
    if not occlusion:
        monkeypatch.setattr(connections, "segment_blocked", nothing_blocked)
    options = {"diffuse_sampling": technique}
    parts = {}
    for kernel in ("fused", "numpy"):
        fused, _ = lens_kernel(sc, RGBColours, options, kernel)
        batch = Batch(sc, light, None, None, RGBColours, options, 100, np.array([0, light.lane.size]),
                      densities=densities, made=[], lens_kernel=fused)
        with np.errstate(all="ignore"):
            parts[kernel] = (lens_samples(batch), batch.rays, batch.nonfinite)
    (fused, rays_f, bad_f), (numpy, rays_n, bad_n) = parts["fused"], parts["numpy"]
    assert (rays_f, bad_f) == (rays_n, bad_n) and bad_f > 0 and fused.count > (1500 if not occlusion else 100)
    fields = ["value", "raster", "lane", "s", "t", "flags"]
    if densities:
        fields += ["qs_fwd", "qs_rev", "qs_minus_rev", "pt_fwd", "pt_rev", "pt_minus_rev"]
        for density in ("qs_minus_rev", "pt_rev"):   # the made-up extremes reach the densities that read them
            values = getattr(fused, density)
            assert (values > 0).any() and (values == 0).any() and not np.isfinite(values).all(), density
    for field in fields:
        same_bits(getattr(fused, field), getattr(numpy, field), field)


# -- what the kernel leaves to NumPy, and its refusals -------------------------------------------------------

def test_scenes_and_settings_the_kernel_does_not_serve_say_why():
    box = scene("cornell-box")
    cases = [
        (scene("cornell-box-thin-lens"), RGBColours, "fused", "a camera other than a pinhole"),
        (scene("cornell-box-point-light"), RGBColours, "fused", "lights other than area lights"),
        (scene("veach-mis"), RGBColours, "fused", "material 'plate1' is conductor"),
        (box, SpectralColours(np.full((4, 1), 550.0), None, None), "fused", "spectral"),
        (box, RGBColours, "numpy", "kernel='numpy'"),
    ]
    for sc, colours, kernel, reason in cases:
        fused, why = lens_kernel(sc, colours, {}, kernel)
        assert fused is None and reason in why
    assert lens_kernel(box, RGBColours, {"diffuse_sampling": "uniform"}, "fused")[0].technique == 1
    assert any("camera in NumPy (a camera other than a pinhole)" in line
               for line in LightTracer().plan(scene("cornell-box-thin-lens")))


def kernel_args(k: int = 3, densities: bool = False):
    sc = scene("cornell-box")
    fused, _ = lens_kernel(sc, RGBColours, {}, "fused")
    v = 4
    vectors = [np.ones((3, v), np.float32)] * 3
    camera = sc.camera
    return [*vectors, np.ones((3, v)), np.zeros(v, np.int64), np.zeros(v, np.int64), np.arange(k, dtype=np.int64),
            np.zeros(k, bool), fused.diffuse, fused.reflectance, fused.radiance, fused.two_sided, camera.position,
            camera.forward, camera.right, camera.image_up, camera.tan_half[0], camera.tan_half[1], camera.width,
            camera.height, camera.lens_area, camera.image_area * camera.lens_area, 0,
            *([np.ones(v)] * 3 if densities else [None] * 3)]


@pytest.mark.parametrize("position, value, error, match", [
    (6, np.array([0, 4, 1]), IndexError, r"chosen\[1\] is not a vertex"),
    (6, np.array([-1, 0, 1]), IndexError, r"chosen\[0\] is not a vertex"),
    (4, np.full(4, 99), IndexError, r"material of chosen\[0\] is not a diffuse material"),
    (8, np.zeros(3, bool), IndexError, r"material of chosen\[0\] is not a diffuse material"),
    (0, np.ones((3, 5), np.float32), ValueError, "must agree"),
    (3, np.ones((4, 4)), ValueError, "must agree"),
    (9, np.ones((3, 2)), ValueError, "must agree"),
    (10, np.ones((3, 1)), ValueError, "must agree"),
    (3, np.ones((3, 4), np.float32), TypeError, "beta"),
    (12, np.ones(2), ValueError, "position must have 3 entries"),
    (22, 2, ValueError, "technique must be 0 .cosine. or 1 .uniform., got 2"),
    (23, np.ones(4), ValueError, "q, q_rev and g_prev must all be None or all"),
    (25, np.ones(4), ValueError, "q, q_rev and g_prev must all be None or all"),
])
def test_lens_connect_refuses_bad_arguments(position, value, error, match):
    args = kernel_args()
    args[position] = value
    with pytest.raises(error, match=match):
        _native.lens_connect(*args)


def test_lens_connect_refuses_a_light_vertex_off_the_emitting_triangles():
    args = kernel_args()
    args[7] = np.ones(3, bool)
    args[5] = np.full(4, 7, np.int64)
    with pytest.raises(IndexError, match=r"light of chosen\[0\] is not an emitting triangle"):
        _native.lens_connect(*args)


@pytest.mark.parametrize("position, value, error, match", [
    (23, np.ones(3), ValueError, "q, q_rev and g_prev must all be None or all"),
    (25, np.ones(5), ValueError, "q, q_rev and g_prev must all be None or all"),
    (24, None, ValueError, "q, q_rev and g_prev must all be None or all"),
    (25, np.ones(4, np.float32), TypeError, "g_prev"),
])
def test_lens_connect_refuses_bad_densities(position, value, error, match):
    args = kernel_args(densities=True)
    args[position] = value
    with pytest.raises(error, match=match):
        _native.lens_connect(*args)


@pytest.mark.parametrize("densities", [False, True])
def test_lens_connect_takes_no_vertices(densities):
    out = _native.lens_connect(*kernel_args(0, densities))
    assert len(out) == (5 if densities else 2)
    assert out[0].shape == (3, 0) and out[1].shape == (2, 0) and all(a.shape == (0,) for a in out[2:])
