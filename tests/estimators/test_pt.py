"""The path tracer's own behaviour: max_depth counts segments, determinism across threads, pass ranges
that add up, seeds, MIS beating each of its strategies, light transport linear in the emitters, the
time budget and stats, its plan, and the parameter checks.  (That every sampling strategy, heuristic
and roulette policy estimates the right image is the agreement matrix, test_agreement.py.)"""
from __future__ import annotations

import re

import numpy as np
import pytest

import pathspace as ps
from pathspace.validate import compare_estimates, furnace_scene
from conftest import mean_and_error, scene_dict


def test_max_depth_counts_segments():
    """In the furnace, paths of at most k segments see Le (1 + rho + ... + rho^(k-1)) exactly in expectation."""
    for depth in (1, 2, 3):
        result = ps.render(furnace_scene(0.5), "pt", spp=16, seed=2, max_depth=depth, rr="off")
        mean, error = mean_and_error(result)
        exact = sum(0.5 ** k for k in range(depth))
        if depth == 1:
            np.testing.assert_allclose(result.image, 1.0)  # only emission seen directly: no noise at all
        else:
            assert abs(mean - exact) < 3 * error + 1e-12


def test_same_seed_same_image_any_thread_count(cornell_small):
    a = ps.render(cornell_small, spp=8, seed=42, threads=1)
    b = ps.render(cornell_small, spp=8, seed=42, threads=2)
    c = ps.render(cornell_small, spp=8, seed=42, threads=3)
    assert np.array_equal(a.image, b.image) and np.array_equal(a.image, c.image)
    assert np.array_equal(a.variance, b.variance)


def test_pass_ranges_add_up(cornell_small):
    """Pass p draws from its own stream: passes 0-3 and 4-7 rendered apart add up to the 8-spp render."""
    first = ps.render(cornell_small, spp=4, seed=9)
    second = ps.render(cornell_small, spp=4, seed=9, first_pass=4)
    whole = ps.render(cornell_small, spp=8, seed=9)
    assert not np.array_equal(first.image, second.image)
    first.film.merge(second.film)
    np.testing.assert_allclose(first.film.sum, whole.film.sum, rtol=1e-12)
    np.testing.assert_allclose(first.film.sum_sq, whole.film.sum_sq, rtol=1e-12)
    np.testing.assert_array_equal(first.film.count, whole.film.count)


def test_different_seeds_differ_but_agree_in_mean(cornell_small):
    a = ps.render(cornell_small, spp=16, seed=1)
    b = ps.render(cornell_small, spp=16, seed=2)
    assert not np.array_equal(a.image, b.image)
    diff = a.image.mean(axis=(0, 1)) - b.image.mean(axis=(0, 1))
    error = np.sqrt(a.variance.sum(axis=(0, 1)) + b.variance.sum(axis=(0, 1))) / (64 * 64)
    assert np.all(np.abs(diff) < 4 * error)



def test_mis_has_less_variance_than_bsdf_sampling_on_the_cornell_box(cornell_small):
    """On the Cornell box's small light, MIS has less than half the variance of BSDF sampling alone."""
    mis = ps.render(cornell_small, spp=64, seed=3, light_sampling="mis")
    bsdf = ps.render(cornell_small, spp=64, seed=3, light_sampling="none")
    assert mis.variance.sum() < 0.5 * bsdf.variance.sum()


def test_mis_beats_both_strategies_on_veachs_scene():
    """MIS is never much worse than the better of its two strategies, and clearly better than each overall."""
    s = ps.scene_from_dict(scene_dict("veach-mis", (96, 64)))
    mis = ps.render(s, spp=128, seed=1)
    nee = ps.render(s, spp=128, seed=4, light_sampling="nee")
    bsdf = ps.render(s, spp=128, seed=5, light_sampling="none")
    assert mis.variance.sum() < 0.5 * nee.variance.sum() and mis.variance.sum() < 0.5 * bsdf.variance.sum()


def test_lights_add_up():
    """Light transport is linear in the emitters: an area light plus an environment renders as the sum of the
    two rendered apart (a shadow-ray bug that hit light surfaces only showed up with both present)."""
    def load(area, env):
        data = scene_dict("cornell-box", (64, 64))
        if env:
            data["lights"] = [{"type": "environment", "radiance": [0.2, 0.3, 0.4]}]
        if not area:
            for shape in data["shapes"]:
                shape.pop("emitter", None)
        return ps.scene_from_dict(data)

    for mode in ("mis", "nee"):
        both = ps.render(load(True, True), spp=256, seed=1, light_sampling=mode, max_depth=3)
        area = ps.render(load(True, False), spp=256, seed=2, light_sampling=mode, max_depth=3)
        env = ps.render(load(False, True), spp=256, seed=3, light_sampling=mode, max_depth=3)
        result = compare_estimates(both.image, both.variance, area.image + env.image, area.variance + env.variance)
        assert result.passed, (mode, str(result))


def test_time_budget_and_stats(cornell_small):
    result = ps.render(cornell_small, time=1.0, seed=1)   # passes even when pytest's workers share the cores
    s = result.stats
    assert s["spp"] >= 1 and np.all(result.film.count == s["spp"])
    assert s["samples"] == s["spp"] * 64 * 64
    assert s["samples_per_second"] > 0 and s["rays"] >= s["samples"]
    assert s["estimator"] == "pt" and s["params"]["max_depth"] == -1



@pytest.mark.parametrize("params, phrases", [
    ({}, ["path tracing, max_depth=unbounded", "Russian roulette from depth 5: survival probability = max throughput",
          "diffuse surfaces sampled cosine-weighted",
          "next-event estimation + BSDF sampling, power heuristic (beta=2); lights chosen by power, points "
          "sampled by area",
          "no specular (delta) materials: no specular code runs"]),
    ({"light_sampling": "mixture", "mixture_alpha": 0.25, "rr": "off", "max_depth": 3},
     ["path tracing, max_depth=3", "no Russian roulette",
      "one direction per vertex from 0.25 p_light + 0.75 p_bsdf; no shadow rays"]),
    ({"light_sampling": "nee", "mis": "balance", "light_selection": "uniform", "light_measure": "solid_angle"},
     ["next-event estimation only"]),
    ({"light_sampling": "none", "diffuse_sampling": "uniform"},
     ["diffuse surfaces sampled uniform-weighted", "BSDF sampling only"]),
])
def test_plan_says_what_runs(cornell_small, params, phrases):
    text = "\n".join(ps.estimators.make_estimator("pt", **params).plan(cornell_small))
    for phrase in phrases:
        assert phrase in text, (phrase, text)


def test_plan_names_delta_lights_and_specular_materials():
    plan = ps.estimators.make_estimator("pt").plan(ps.scene_from_dict(scene_dict("cornell-box-point-light")))
    assert "point/spot/directional lights: light sampling only (BSDF samples cannot hit them)" in plan
    plan = ps.estimators.make_estimator("pt").plan(ps.scene_from_dict(scene_dict("cornell-box-specular")))
    assert any(re.fullmatch(r"specular \(delta\) materials: .+: no light sampling at their vertices", line)
               for line in plan), plan


@pytest.mark.parametrize("kwargs, match", [
    ({"spp": 0}, "spp: expected an integer >= 1"),
    ({"spp": 4, "time": 1.0}, "either spp or time"),
    ({"time": -1.0}, "time: expected a number of seconds > 0"),
    ({"seed": -3}, "seed: expected an integer >= 0"),
    ({"threads": 0}, "threads: expected an integer >= 1"),
    ({"max_depth": 0}, "max_depth: expected -1"),
    ({"light_sampling": "all"}, "light_sampling: expected one of"),
    ({"rr": "sometimes"}, "rr: expected one of"),
    ({"rr_probability": 1.0}, "rr_probability"),
    ({"mis_beta": float("nan")}, "mis_beta"),
    ({"bounces": 3}, "estimator 'pt' has no parameter"),
])
def test_bad_render_arguments(cornell_small, kwargs, match):
    with pytest.raises(ValueError, match=match):
        ps.render(cornell_small, **kwargs)


def test_unknown_estimator(cornell_small):
    with pytest.raises(ValueError, match="unknown estimator 'vcm'; available: pt"):
        ps.render(cornell_small, "vcm")



def test_mixture_alpha_one_is_refused():
    with pytest.raises(ValueError, match=r"mixture_alpha: expected a number in \[0, 1\)"):
        ps.estimators.make_estimator("pt", light_sampling="mixture", mixture_alpha=1.0)

