"""Light tracing and BDPT, beyond agreement (which is the matrix, test_agreement.py): every single
strategy (s, t) estimates the same length-k contribution, infeasible strategies contribute nothing,
sky light reaches a far thin lens, long paths stay finite, multi-tile passes, determinism across threads,
the strategy pyramid adds up to the image, the plans, and the parameter checks."""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from conftest import agree, no_nonfinite, scene_dict, sky_quad_scene


def scene(name: str, resolution=(32, 32), **camera) -> ps.Scene:
    data = scene_dict(name, resolution)
    data["camera"].update(camera)
    return ps.scene_from_dict(data, source=name)


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
    lights are never even formed; their zero weights are tested on the MIS kernel, tests/test_mis.py.)"""
    env = sky_quad_scene()
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



def long_path_furnace(resolution):
    data = scene_dict("furnace", resolution)
    data["materials"]["wall"]["reflectance"] = [0.99] * 3
    return ps.scene_from_dict(data)


def test_long_paths_stay_finite():
    """Albedo 0.99: subpaths of more than 200 vertices occur; every weight and sample stays finite."""
    result = ps.render(long_path_furnace((4, 4)), "bdpt", spp=8, seed=6)
    assert result.stats["longest_subpath"] > 200
    assert no_nonfinite(result) and np.all(np.isfinite(result.image)) and np.all(result.image > 0)


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



def test_plans():
    """The plan says what runs: the heuristic, the roulette, the strategies a camera or light rules out."""
    bdpt = ps.estimators.make_estimator("bdpt")
    text = "\n".join(bdpt.plan(scene("cornell-box-thin-lens", (8, 8))))
    assert "bidirectional path tracing, max_depth=unbounded; power heuristic (beta=2)" in text
    assert "Russian roulette from depth 1: survival probability = material albedo" in text
    assert "thin-lens camera: t = 0 strategy (light subpaths passing through the lens)" in text
    text = "\n".join(bdpt.plan(scene("cornell-box-point-light", (8, 8))))
    assert "pinhole camera: no t = 0 strategy (rays cannot hit it)" in text
    assert "point/spot/directional lights: no s = 0 strategy for their paths (rays cannot hit them)" in text
    text = "\n".join(ps.estimators.make_estimator("lt", rr="throughput").plan(scene("cornell-box-specular", (8, 8))))
    assert "light tracing, max_depth=unbounded" in text
    assert "Russian roulette from depth 1: survival probability = max throughput" in text
    assert "specular materials (mirror, glass): paths reaching the camera only through them are not formed" in text


def test_parameter_errors():
    with pytest.raises(ValueError, match=r"strategy: mis='single' needs \(s, t\)"):
        ps.estimators.make_estimator("bdpt", mis="single")
    with pytest.raises(ValueError, match=r"mis: expected one of"):
        ps.estimators.make_estimator("bdpt", mis="maximum")
    for name in ("lt", "bdpt"):
        with pytest.raises(ValueError, match=r"rr: expected one of \('off', 'fixed', 'albedo', 'throughput'\)"):
            ps.estimators.make_estimator(name, rr="sometimes")
        # One roulette vocabulary: the throughput policy is accepted (it used to be path tracing's alone).
        assert ps.estimators.make_estimator(name, rr="throughput").roulette.policy == "throughput"
    with pytest.raises(ValueError, match=r"max_depth"):
        ps.estimators.make_estimator("bdpt", max_depth=0)
    with pytest.raises(ValueError, match=r"longer than max_depth=2"):
        ps.estimators.make_estimator("bdpt", mis="single", strategy=(2, 2), max_depth=2)


@pytest.mark.parametrize("params, camera, light", [
    ({}, True, False), ({"mis_roulette": "camera"}, True, False), ({"rr": "fixed"}, True, True),
    ({"light_rr": "fixed"}, True, True), ({"rr": "fixed", "light_rr": "albedo"}, True, False),
    ({"light_rr": "throughput"}, True, True), ({"light_rr": "fixed", "mis_roulette": "camera"}, True, False),
    ({"light_rr": "fixed", "mis_roulette": "none"}, False, False)])
def test_auto_leaves_out_only_a_light_roulette_that_keeps_the_throughput_level(params, camera, light):
    """mis_roulette "auto" (the default) leaves the light subpaths' survival out of the MIS densities only where
    their roulette is "albedo" (a "fixed" survival below the albedo raises their throughput, and left out it
    had 36 times the error on the diffuse box); the camera subpaths' is in.  A choice made is kept."""
    bdpt = ps.estimators.make_estimator("bdpt", **params)
    assert (bdpt.roulette.in_mis, bdpt.light_roulette.in_mis) == (camera, light)
    walks = " and ".join(name for name, used in (("camera", camera), ("light", light and params.get("light_rr")
                                                                                    != "throughput")) if used)
    assert (f"the {walks} subpaths' survival" if walks else "no survival probabilities") in bdpt._roulette_plan()


def test_light_tracing_takes_the_caustic_under_the_glass_sphere():
    """The caustic under the glass sphere (light, glass, glass, floor, camera) has two strategies: light tracing
    (s = 4, t = 1), which renders it smoothly, and the camera walk finding the light through the sphere (s = 0).
    With the geometry of the specular vertices in the MIS densities (subpaths' module docstring), light tracing
    takes 99% of it on its brightest pixels (reading the deltas' densities as 1, pbrt's convention, gave it 5%:
    the floor is close to the sphere where it rests on it, and the s = 0 walk's density was inflated by that
    segment's geometry term)."""
    box = ps.scene_from_dict(scene_dict("cornell-box-specular", (48, 48)))
    result = ps.render(box, "bdpt", spp=16, seed=1, pyramid=4)
    unweighted = result.film.layer_mean("s4t1.unweighted").sum(axis=-1).ravel()
    weighted = result.film.layer_mean("s4t1.weighted").sum(axis=-1).ravel()
    caustic = np.argsort(unweighted)[::-1][:12]
    # the caustic: five pixels brighter than the lit floor around it (1.3-2.3 against at most 0.45 at 16-128 spp)
    assert unweighted[caustic[4]] > 1.0
    assert weighted[caustic].sum() / unweighted[caustic].sum() > 0.9


@pytest.mark.parametrize("mis_roulette", ["both", "light", "none"])
def test_survival_in_the_mis_densities_changes_the_weights_only(mis_roulette):
    """Which subpaths' roulette enters the MIS densities changes the weights, not the paths: the same rays and
    bit for bit the same unweighted strategy images; the weighted ones differ where both subpaths take part."""
    box = scene("cornell-box", (16, 16))
    default = ps.render(box, "bdpt", spp=4, seed=3, pyramid=3)
    other = ps.render(box, "bdpt", spp=4, seed=3, pyramid=3, mis_roulette=mis_roulette)
    assert default.stats["rays"] == other.stats["rays"] and default.stats["params"]["mis_roulette"] == "auto"
    names = [name for name in default.film.layers if name.endswith(".unweighted")]
    assert len(names) >= 6
    for name in names:
        np.testing.assert_array_equal(other.film.layer_mean(name), default.film.layer_mean(name))
    moved = [name for name in default.film.layers if name.endswith(".weighted")
             and not np.array_equal(other.film.layer_mean(name), default.film.layer_mean(name))]
    # paths of one segment (s0t2, s1t1) meet no roulette; paths of three segments do
    assert {"s0t2.weighted", "s1t1.weighted", "s2t2.weighted"} <= set(default.film.layers)
    assert "s2t2.weighted" in moved and "s0t2.weighted" not in moved and "s1t1.weighted" not in moved
    line = {"both": "the camera and light subpaths' survival", "light": "the light subpaths' survival",
            "none": "no survival probabilities"}[mis_roulette]
    assert line in other.stats["plan"][1] and "the camera subpaths' survival" in default.stats["plan"][1]
