"""The path tracer: analytic furnaces, determinism, and agreement of its light-sampling modes."""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace.validate import furnace_radiance, furnace_scene


def image_mean_and_error(result, channel=0):
    """Mean over pixels of one channel and its standard error (pixels are independent)."""
    values = result.image[..., channel]
    return values.mean(), np.sqrt(result.variance[..., channel].sum()) / values.size


@pytest.mark.parametrize("albedo", [0.5, 0.9, 0.99])
def test_furnace_matches_analytic_radiance(albedo):
    result = ps.render(furnace_scene(albedo), "pt", spp=64, seed=11)
    exact = furnace_radiance(albedo, 1.0)
    mean, error = image_mean_and_error(result)
    assert error < 0.01 * exact  # the test has the power to see a 3% bias
    assert abs(mean - exact) < 3 * error, (mean, exact, error)
    assert result.stats["nonfinite"] == 0
    # Every channel, not just the first.
    np.testing.assert_allclose(result.image.mean(axis=(0, 1)), exact, rtol=6 * error / exact)


# NEE alone (and uniform MIS, which gives NEE half the weight) is left out here: in a furnace, light
# samples on the wall next to the receiver make its variance infinite at the cube's edges
# (G = cos cos / d^2), so its error bars are meaningless.  The Cornell box tests cover them.
@pytest.mark.parametrize("params", [{"light_sampling": "none"}, {"light_sampling": "mixture"},
                                   {"mis": "balance"}, {"rr": "off", "max_depth": 400},
                                   {"rr": "fixed", "rr_depth": 2, "rr_probability": 0.3}, {"rr": "albedo"},
                                   {"diffuse_sampling": "uniform"}, {"light_measure": "solid_angle"},
                                   {"light_selection": "uniform"}])
def test_furnace_with_other_strategies(params):
    result = ps.render(furnace_scene(0.8), "pt", spp=32, seed=5, **params)
    mean, error = image_mean_and_error(result)
    assert abs(mean - 5.0) < 3 * error and error < 0.1  # 2% of the answer


def test_max_depth_counts_segments():
    """In the furnace, paths of at most k segments see Le (1 + rho + ... + rho^(k-1)) exactly in expectation."""
    for depth in (1, 2, 3):
        result = ps.render(furnace_scene(0.5), "pt", spp=16, seed=2, max_depth=depth, rr="off")
        mean, error = image_mean_and_error(result)
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


def test_light_sampling_modes_agree_on_the_cornell_box(cornell_small):
    """MIS, NEE only and BSDF only estimate the same image (global means, per channel)."""
    results = {mode: ps.render(cornell_small, spp=64, seed=3, light_sampling=mode) for mode in ("mis", "nee", "none")}
    ref = results["mis"]
    for mode in ("nee", "none"):
        r = results[mode]
        diff = r.image.mean(axis=(0, 1)) - ref.image.mean(axis=(0, 1))
        error = np.sqrt(r.variance.sum(axis=(0, 1)) + ref.variance.sum(axis=(0, 1))) / (64 * 64)
        assert np.all(np.abs(diff) < 4 * error), (mode, diff, error)
    # MIS has lower variance than BSDF sampling alone on this small light.
    assert results["mis"].variance.sum() < 0.5 * results["none"].variance.sum()


def test_time_budget_and_stats(cornell_small):
    result = ps.render(cornell_small, time=0.5, seed=1)
    s = result.stats
    assert s["spp"] >= 1 and np.all(result.film.count == s["spp"])
    assert s["samples"] == s["spp"] * 64 * 64
    assert s["samples_per_second"] > 0 and s["rays"] >= s["samples"]
    assert s["estimator"] == "pt" and s["params"]["max_depth"] == -1


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
    with pytest.raises(ValueError, match="unknown estimator 'mlt'; available: pt"):
        ps.render(cornell_small, "mlt")
