"""Light tracing and BDPT: agreement with path tracing, per-strategy agreement, infeasible strategies,
long paths, scale and extremes, determinism, the strategy pyramid."""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace.validate import furnace_radiance
from conftest import agree, scaled, scene_dict


def scene(name: str, resolution=(32, 32), **camera) -> ps.Scene:
    data = scene_dict(name, resolution)
    data["camera"].update(camera)
    return ps.scene_from_dict(data, source=name)


def no_nonfinite(result) -> bool:
    """Neither a pixel sample nor a connection was dropped for a NaN or Inf."""
    return result.stats["nonfinite"] == 0 and result.stats["nonfinite_contributions"] == 0


def mean_and_error(result, channel=0):
    values = result.image[..., channel]
    return values.mean(), np.sqrt(result.variance[..., channel].sum()) / values.size


REFERENCE_SPP = {"cornell-box": 2048, "cornell-box-specular": 4096, "cornell-box-point-light": 2048,
                 "cornell-box-thin-lens": 2048}


@pytest.fixture(scope="module")
def references():
    cache = {}

    def get(name):
        if name not in cache:
            s = scene(name)
            cache[name] = (s, ps.render(s, "pt", spp=REFERENCE_SPP[name], seed=1))
        return cache[name]
    return get


@pytest.mark.parametrize("name", ["cornell-box", "cornell-box-point-light", "cornell-box-thin-lens"])
@pytest.mark.parametrize("estimator, params, spp", [
    ("lt", {}, 256), ("bdpt", {"mis": "power"}, 256), ("bdpt", {"mis": "balance"}, 256),
    ("bdpt", {"mis": "uniform"}, 512), ("bdpt", {"mis": "power", "rr": "fixed", "rr_probability": 0.3}, 256)],
    ids=lambda v: str(v))
def test_estimators_agree_with_path_tracing(references, name, estimator, params, spp):
    s, reference = references(name)
    if name == "cornell-box-thin-lens" and params.get("mis") == "uniform":
        # Uniform weights give the lens-hit strategy (t = 0) 1 / (k + 2) of every path; through the
        # 0.08 aperture it contributes rarely and hugely (most pixels 5% low, a few 10x high), too
        # heavy-tailed for error bars.  A 0.5 aperture keeps the same strategies well behaved.
        s = scene(name, aperture_radius=0.5)
        reference = ps.render(s, "pt", spp=REFERENCE_SPP[name], seed=1)
    result = ps.render(s, estimator, spp=spp, seed=2, **params)
    assert no_nonfinite(result)
    ok, report = agree(reference, result)
    assert ok, report


def seen_through_specular(s: ps.Scene, rays_per_pixel=16) -> np.ndarray:
    """(H, W) bool: some primary ray of the pixel first hits a specular (delta) surface."""
    camera = s.camera
    rng = np.random.default_rng(0)
    pixels = np.repeat(np.arange(camera.pixel_count), rays_per_pixel)
    origin, direction = camera.generate_rays(pixels, rng.random((2, pixels.size)), rng.random((2, pixels.size)))
    hits = s.accel.intersect(origin, direction)
    material = np.where(hits.prim >= 0, s.mesh.material.take(np.maximum(hits.prim, 0)), -1)
    delta = np.where(material >= 0, s.materials.delta.take(np.maximum(material, 0)), False)
    return np.bincount(pixels, weights=delta, minlength=camera.pixel_count).reshape(camera.height, camera.width) > 0


def test_specular_cornell_box(references):
    """Glass and mirror: BDPT agrees with path tracing; light tracing wherever the camera sees no
    specular surface (elsewhere it cannot form the paths), and it renders the caustics."""
    s, reference = references("cornell-box-specular")
    for mis in ("power", "balance"):
        result = ps.render(s, "bdpt", spp=512, seed=3, mis=mis)
        ok, report = agree(reference, result)
        assert ok, (mis, report)
    lt = ps.render(s, "lt", spp=512, seed=4)
    visible = ~seen_through_specular(s)
    assert 0.1 < (~visible).mean() < 0.5
    ok, report = agree(reference, lt, mask=visible)
    assert ok, report


def test_furnace_bdpt_and_lt():
    """Uniform emission Le and albedo rho everywhere: L = Le / (1 - rho) in every pixel."""
    for rho in (0.5, 0.9):
        data = scene_dict("furnace", (16, 16))
        data["materials"]["wall"]["reflectance"] = [rho] * 3
        s = ps.scene_from_dict(data)
        for estimator, spp in (("lt", 256), ("bdpt", 32)):
            result = ps.render(s, estimator, spp=spp, seed=5)
            mean, error = mean_and_error(result)
            exact = furnace_radiance(rho, 1.0)
            assert error < 0.01 * exact and abs(mean - exact) < 3 * error, (estimator, rho, mean, error)


def long_path_furnace(resolution):
    data = scene_dict("furnace", resolution)
    data["materials"]["wall"]["reflectance"] = [0.99] * 3
    return ps.scene_from_dict(data)


def test_long_paths_stay_finite():
    """Albedo 0.99: subpaths of more than 200 vertices occur; every weight and sample stays finite."""
    result = ps.render(long_path_furnace((4, 4)), "bdpt", spp=8, seed=6)
    assert result.stats["longest_subpath"] > 200
    assert no_nonfinite(result) and np.all(np.isfinite(result.image)) and np.all(result.image > 0)


@pytest.mark.slow
def test_long_path_furnace_matches_analytic():
    result = ps.render(long_path_furnace((8, 8)), "bdpt", spp=64, seed=7)
    mean, error = mean_and_error(result)
    assert result.stats["longest_subpath"] > 200 and no_nonfinite(result)
    assert error < 0.02 * 100.0 and abs(mean - 100.0) < 3 * error, (mean, error)


@pytest.mark.parametrize("length", [1, 2, 3])
def test_every_single_strategy_estimates_the_same_length_k_contribution(length):
    """For paths of exactly k segments, each strategy (s, t), s + t = k + 1, alone (weight 1) estimates
    the same image -- on a thin-lens camera, so t = 0 (light subpaths hitting the lens) is among them."""
    s = scene("cornell-box-thin-lens", (16, 16), aperture_radius=0.5)
    reference = ps.render(s, "bdpt", spp=1024, seed=8, mis="single", strategy=(1, length), max_depth=length)
    assert reference.image.mean() > 0
    for first in range(length + 2):
        st = (first, length + 1 - first)
        if st == (1, length):
            continue
        spp = 4096 if st[1] == 0 else 1024
        result = ps.render(s, "bdpt", spp=spp, seed=9, mis="single", strategy=st, max_depth=length)
        ok, report = agree(reference, result, block=16)
        assert ok, (st, report)


def test_infeasible_strategies_contribute_nothing():
    """(1, 1) cannot join a camera point to a light at infinity: with only an environment its image is
    exactly zero while BDPT still agrees with path tracing.  (t = 0 with a pinhole and s = 0 with point
    lights are never even formed; their zero weights are tested on the MIS kernel, test_bdpt_mis.py.)"""
    env = ps.scene_from_dict({
        "camera": {"position": [0, 0, 5], "look_at": [0, 0, 0], "fov": 30, "resolution": [8, 8]},
        "materials": {"grey": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
        "shapes": [{"type": "quad", "corner": [-1, -1, 0], "edge_u": [2, 0, 0], "edge_v": [0, 2, 0],
                    "material": "grey"}],
        "lights": [{"type": "environment", "radiance": [1, 1, 1]}]})
    assert not ps.render(env, "bdpt", spp=16, seed=1, mis="single", strategy=(1, 1)).image.any()
    assert ps.render(env, "bdpt", spp=16, seed=1, mis="single", strategy=(0, 2)).image.any()
    both = ps.render(env, "bdpt", spp=64, seed=2)
    reference = ps.render(env, "pt", spp=256, seed=3)
    ok, report = agree(reference, both)
    assert ok, report


def test_sky_light_hits_a_thin_lens_far_outside_the_geometry():
    """Sky rays start on a disk around the geometry *and* the lens: a lens 5 units from a 0.2-wide quad
    still receives them.  Strategy (2, 0) alone (sky -> lens) reproduces the sky seen directly."""
    s = ps.scene_from_dict({
        "camera": {"type": "thinlens", "position": [0, 0, 5], "look_at": [0, 0, 0], "fov": 40, "resolution": [8, 8],
                   "aperture_radius": 1.0, "focus_distance": 5.0},
        "materials": {"grey": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
        "shapes": [{"type": "quad", "corner": [-0.1, -0.1, 0], "edge_u": [0.2, 0, 0], "edge_v": [0, 0.2, 0],
                    "material": "grey"}],
        "lights": [{"type": "environment", "radiance": [1, 1, 1]}]})
    lights, camera = s.lights, s.camera
    assert np.linalg.norm(camera.position - lights.context.disk_center) + camera.lens_radius <= lights.context.disk_radius
    hits = ps.render(s, "bdpt", spp=16384, seed=1, mis="single", strategy=(2, 0), max_depth=1)
    reference = ps.render(s, "pt", spp=64, seed=2, max_depth=1)
    sky = np.all(reference.variance < 1e-12, axis=-1) & (reference.image[..., 0] > 0.999)
    assert sky.sum() > 40
    mean, error = hits.image[sky].mean(), np.sqrt(hits.variance[sky][:, 0].sum()) / sky.sum()
    assert abs(mean - 1.0) < 4 * error and error < 0.03, (mean, error)


def open_scene(camera: dict) -> ps.Scene:
    """Outdoors: a Phong floor and a rough GGX box under an environment, a directional light, a spot
    light, a point light and a two-sided area light, seen from far outside the geometry."""
    return ps.scene_from_dict({
        "camera": {"position": [0, 1.5, 9], "look_at": [0, 0.3, 0], "fov": 30, "resolution": [32, 32], **camera},
        "materials": {"floor": {"type": "phong", "diffuse": [0.5, 0.45, 0.4], "specular": [0.3, 0.3, 0.3],
                                "exponent": 20},
                      "metal": {"type": "conductor", "eta": [0.2, 0.4, 1.5], "k": [3.9, 2.4, 1.8], "alpha": 0.3},
                      "lamp": {"type": "diffuse", "reflectance": [0.2, 0.2, 0.2]}},
        "shapes": [{"type": "quad", "corner": [-3, 0, 3], "edge_u": [6, 0, 0], "edge_v": [0, 0, -6],
                    "material": "floor"},
                   {"type": "box", "center": [0.4, 0.5, 0], "size": [1, 1, 1], "material": "metal"},
                   {"type": "quad", "corner": [-1.5, 1.2, -0.5], "edge_u": [0.6, 0, 0], "edge_v": [0, 0.6, 0],
                    "material": "lamp", "emitter": {"radiance": [3, 3, 3], "two_sided": True}}],
        "lights": [{"type": "environment", "radiance": [0.3, 0.35, 0.45]},
                   {"type": "directional", "direction": [-1, -2, -0.5], "irradiance": [1.5, 1.4, 1.2]},
                   {"type": "spot", "position": [1.5, 2.5, 1.5], "look_at": [0, 0, 0], "intensity": [8, 6, 4],
                    "cone_angle": 25},
                   {"type": "point", "position": [-1, 1.5, 1.5], "intensity": [1, 2, 2]}]})


@pytest.mark.parametrize("camera", [{}, {"type": "thinlens", "aperture_radius": 0.3, "focus_distance": 9.0}],
                         ids=["pinhole", "thin-lens"])
def test_every_light_kind_outdoors(camera):
    """Environment (also seen directly, through the lens), directional, spot, point and a two-sided
    area light, Phong and GGX, the camera outside the geometry: BDPT (power and balance) agrees with
    path tracing."""
    s = open_scene(camera)
    reference = ps.render(s, "pt", spp=1024, seed=1)
    # Where only the sky is seen, path tracing is exact (zero variance) while through a lens BDPT gives
    # about 3e-5 of the radiance to rare lens hits (t = 0) of sky rays: a block test with near-zero
    # variance would flag that noise, so those pixels are checked against the sky instead: their mean
    # within 2e-4, each pixel (one lens hit adds about 0.5% at 256 spp) within 1e-2.
    sky = np.all(reference.variance < 1e-12, axis=-1)
    assert 0 < sky.sum() < sky.size
    for params in ({"mis": "power"}, {"mis": "balance"}):
        result = ps.render(s, "bdpt", spp=256, seed=2, **params)
        assert no_nonfinite(result)
        ok, report = agree(reference, result, mask=~sky)
        assert ok, (params, report)
        np.testing.assert_allclose(result.image[sky].mean(0), reference.image[sky].mean(0), rtol=2e-4)
        np.testing.assert_allclose(result.image[sky], reference.image[sky], rtol=1e-2)


def test_multi_tile_passes(monkeypatch):
    """Images larger than one item (a pass split over tiles) assemble their splats pass by pass: the
    same on one or two threads, and the same image as path tracing."""
    from pathspace.estimators.bidirectional import Bidirectional

    monkeypatch.setattr(Bidirectional, "tile_pixels", 1000)  # 64 x 64 pixels: 5 tiles per pass
    s = scene("cornell-box", (64, 64))
    one = ps.render(s, "lt", spp=2, seed=3, threads=1)
    np.testing.assert_array_equal(one.image, ps.render(s, "lt", spp=2, seed=3, threads=2).image)
    lt = ps.render(s, "lt", spp=32, seed=4)
    ok, report = agree(ps.render(s, "pt", spp=64, seed=5), lt, block=16)
    assert ok, report


@pytest.mark.parametrize("factor", [1e-6, 1e6])
def test_scale_invariance(factor):
    data = scene_dict("cornell-box")
    reference = ps.render(ps.scene_from_dict(data), "bdpt", spp=128, seed=1)
    other = ps.render(ps.scene_from_dict(scaled(data, factor)), "bdpt", spp=128, seed=2)
    assert no_nonfinite(other) and other.image.mean() > 0.1
    ok, report = agree(reference, other)
    assert ok, report


def extreme_scenes():
    tiny = scene_dict("cornell-box", (16, 16))
    tiny["materials"]["black"] = {"type": "diffuse", "reflectance": [0, 0, 0]}
    # Facing the ceiling 0.02 away, so the camera sees its dark back: seen directly, it would land in one
    # pixel through light tracing (1, 1) while camera rays never hit it.
    tiny["shapes"][0] = {"type": "quad", "corner": [0, 0.98, 0], "edge_u": [0, 0, 1e-4], "edge_v": [1e-4, 0, 0],
                         "material": "black", "emitter": {"radiance": [1e8, 1e8, 1e8]}}
    glossy = scene_dict("cornell-box", (16, 16))
    glossy["materials"]["metal"] = {"type": "conductor", "eta": [0.2, 0.4, 1.5], "k": [3.9, 2.4, 1.8],
                                    "alpha": 1e-4}
    glossy["shapes"][1]["material"] = "metal"  # the floor
    grazing = scene_dict("cornell-box", (16, 16))
    grazing["camera"].update(position=[0.0, -0.999, 0.99], look_at=[0.0, -0.9999, -1.0])
    return {"tiny-bright-light": tiny, "ggx-1e-4-floor": glossy, "grazing-camera": grazing}


@pytest.mark.parametrize("name", list(extreme_scenes()))
def test_extremes_are_finite_and_agree_with_path_tracing(name):
    s = ps.scene_from_dict(extreme_scenes()[name])
    result = ps.render(s, "bdpt", spp=256, seed=2)
    assert no_nonfinite(result) and np.all(np.isfinite(result.image)) and result.image.mean() > 0
    if name == "tiny-bright-light":
        # Its light reaches most of the box through a hot spot on the ceiling that path tracing's camera
        # paths find only by chance (spiky, far from converged at any affordable spp): path tracing is
        # compared where it is reliable (direct light), light tracing on the whole image.
        direct = ps.render(s, "bdpt", spp=256, seed=3, max_depth=2)
        ok, report = agree(ps.render(s, "pt", spp=1024, seed=1, max_depth=2), direct, block=4)
        assert ok, report
        reference = ps.render(s, "lt", spp=1024, seed=1)
    else:
        reference = ps.render(s, "pt", spp=1024, seed=1)
    ok, report = agree(reference, result, block=4)
    assert ok, report


def test_spectral_bdpt_with_dispersion_and_rgb_agreement():
    """Spectral BDPT: a flat-spectrum Cornell box matches RGB; dispersive glass before white stays white."""
    data = scene_dict("cornell-box", (16, 16))
    for material in data["materials"].values():
        material["reflectance"] = [0.6] * 3
    data["shapes"][0]["emitter"] = {"radiance": {"illuminant": "E", "scale": 15.0}}
    s = ps.scene_from_dict(data)
    ok, report = agree(ps.render(s, "bdpt", spp=128, seed=1, spectral=False),
                       ps.render(s, "bdpt", spp=128, seed=2, spectral=True))
    assert ok, report
    slab = ps.scene_from_dict({
        "camera": {"position": [0, 0, 5], "look_at": [0, 0, 0], "fov": 10, "resolution": [8, 8]},
        "materials": {"glass": {"type": "dielectric", "ior": {"cauchy": [1.5046, 0.0042]}},
                      "grey": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
        "shapes": [{"type": "box", "center": [0, 0, 0], "size": [4, 4, 1], "material": "glass"}],
        "lights": [{"type": "environment", "radiance": [1, 1, 1]}]})
    result = ps.render(slab, "bdpt", spp=256, seed=3, spectral=True)
    mean = result.image.mean(axis=(0, 1))
    error = np.sqrt(result.variance.sum(axis=(0, 1))) / 64
    assert np.all(np.abs(mean - 1.0) < 4 * error) and np.all(error < 0.03), (mean, error)
    # A diffuse floor under the slab, lit through it: light subpaths cross the dispersive glass
    # (terminating the lane's secondary wavelengths) while some connections avoid it.  The lamp is an
    # area light: path tracing cannot find a point light's caustic through glass, BDPT can.
    floor = ps.scene_from_dict({
        "camera": {"position": [0, 4, 4], "look_at": [0, 0, 0], "fov": 40, "resolution": [16, 16]},
        "materials": {"glass": {"type": "dielectric", "ior": {"cauchy": [1.5046, 0.0042]}},
                      "grey": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
        "shapes": [{"type": "box", "center": [0, 0.6, 0], "size": [1.5, 0.3, 1.5], "material": "glass"},
                   {"type": "quad", "corner": [-3, 0, 3], "edge_u": [6, 0, 0], "edge_v": [0, 0, -6],
                    "material": "grey"},
                   {"type": "quad", "corner": [-0.5, 3, -0.5], "edge_u": [1, 0, 0], "edge_v": [0, 0, 1],
                    "material": "grey", "emitter": {"radiance": [6, 6, 6]}}],
        "lights": [{"type": "environment", "radiance": [0.2, 0.2, 0.2]}]})
    ok, report = agree(ps.render(floor, "pt", spp=1024, seed=4, spectral=True),
                       ps.render(floor, "bdpt", spp=256, seed=5, spectral=True))
    assert ok, report


def test_determinism_across_threads():
    s = scene("cornell-box-thin-lens", (24, 20))
    one = ps.render(s, "bdpt", spp=4, seed=3, threads=1)
    two = ps.render(s, "bdpt", spp=4, seed=3, threads=2)
    np.testing.assert_array_equal(one.image, two.image)
    assert not np.array_equal(one.image, ps.render(s, "bdpt", spp=4, seed=4, threads=1).image)


def test_pyramid_sums_to_the_image():
    """With max_depth = pyramid, the weighted strategy images add up to the image (per-strategy
    agreement of the unweighted images is tested with mis="single" above)."""
    s = scene("cornell-box", (16, 16))
    result = ps.render(s, "bdpt", spp=64, seed=5, max_depth=3, pyramid=3)
    assert set(result.strategies) == {(a, k + 1 - a) for k in (1, 2, 3) for a in range(k + 1)}  # no t = 0: pinhole
    total = sum(images["weighted"] for images in result.strategies.values())
    np.testing.assert_allclose(total, result.image, rtol=1e-9, atol=1e-12)
    for images in result.strategies.values():  # each strategy's weighted part is a fraction of its whole
        assert np.all(images["weighted"] <= images["unweighted"] + 1e-12) and images["unweighted"].max() > 0


def test_parameter_errors():
    with pytest.raises(ValueError, match=r"strategy: mis='single' needs \(s, t\)"):
        ps.estimators.make_estimator("bdpt", mis="single")
    with pytest.raises(ValueError, match=r"mis: expected one of"):
        ps.estimators.make_estimator("bdpt", mis="maximum")
    with pytest.raises(ValueError, match=r"rr: expected one of"):
        ps.estimators.make_estimator("lt", rr="throughput")
    with pytest.raises(ValueError, match=r"max_depth"):
        ps.estimators.make_estimator("bdpt", max_depth=0)
    with pytest.raises(ValueError, match=r"longer than max_depth=2"):
        ps.estimators.make_estimator("bdpt", mis="single", strategy=(2, 2), max_depth=2)
