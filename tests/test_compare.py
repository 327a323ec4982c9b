"""The estimator comparison: calibrated on noise, sensitive to small biases, and used on real renders."""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace.validate import compare_estimates


def noisy_pair(rng, shape=(64, 64, 3), bias=0.0, samples=16):
    truth = rng.uniform(0.1, 2.0, shape)
    out = []
    for extra in (0.0, bias):
        draws = truth[None] * (1 + extra) + rng.normal(0, 0.5, (samples, *shape))
        out += [draws.mean(axis=0), draws.var(axis=0, ddof=1) / samples]
    return out


def test_false_alarm_rate_is_about_alpha():
    rng = np.random.default_rng(0)
    failures = sum(not compare_estimates(*noisy_pair(rng), alpha=0.05).passed for _ in range(200))
    assert failures <= 25  # expected about 10 (5%); 25 has probability < 1e-4 for a calibrated test


def test_detects_a_two_percent_bias():
    rng = np.random.default_rng(1)
    result = compare_estimates(*noisy_pair(rng, bias=0.02, samples=64))
    assert not result.passed and "DIFFERENT" in str(result)


def test_detects_a_local_difference():
    rng = np.random.default_rng(2)
    a, va, b, vb = noisy_pair(rng, samples=64)
    b[8:16, 40:48, 1] += 0.5  # one wrong block
    result = compare_estimates(a, va, b, vb)
    assert not result.passed and result.worst_block == (1, 5, 1)


def test_input_checks():
    with pytest.raises(ValueError, match="same"):
        compare_estimates(np.zeros((4, 4, 3)), np.ones((4, 4, 3)), np.zeros((4, 5, 3)), np.ones((4, 5, 3)))
    with pytest.raises(ValueError, match="finite"):
        compare_estimates(np.zeros((4, 4, 3)), np.full((4, 4, 3), np.inf), np.zeros((4, 4, 3)), np.ones((4, 4, 3)))


def test_path_tracer_strategies_estimate_the_same_image(cornell_small):
    reference = ps.render(cornell_small, spp=64, seed=1)
    for seed, params in enumerate([{"light_sampling": "nee"}, {"mis": "balance"}, {"rr": "albedo", "rr_depth": 1}],
                                  start=2):
        other = ps.render(cornell_small, spp=64, seed=seed, **params)
        result = compare_estimates(reference.image, reference.variance, other.image, other.variance, alpha=0.001)
        assert result.passed, (params, str(result))
    # ... and it notices a truncated path length.
    truncated = ps.render(cornell_small, spp=64, seed=9, max_depth=4)
    assert not compare_estimates(reference.image, reference.variance, truncated.image, truncated.variance).passed


@pytest.mark.slow
def test_cornell_box_strategies_agree_at_full_resolution(cornell):
    """256x256: MIS (power), NEE only and BSDF only, and every roulette policy, block by block."""
    reference = ps.render(cornell, spp=256, seed=1)
    cases = [{"light_sampling": "nee"}, {"light_sampling": "none"}, {"mis": "balance"}, {"rr": "off"},
             {"rr": "fixed", "rr_depth": 3, "rr_probability": 0.2}, {"rr": "albedo", "rr_depth": 2}]
    for seed, params in enumerate(cases, start=2):
        spp = 1024 if params.get("light_sampling") == "none" else 256
        other = ps.render(cornell, spp=spp, seed=seed, **params)
        result = compare_estimates(reference.image, reference.variance, other.image, other.variance, alpha=0.001)
        assert result.passed, (params, str(result))


@pytest.mark.slow
def test_furnace_to_a_tenth_of_a_percent():
    from pathspace.validate import furnace_radiance, furnace_scene

    for albedo in (0.5, 0.9, 0.99):
        result = ps.render(furnace_scene(albedo, resolution=(64, 64)), spp=256 if albedo < 0.99 else 128, seed=4)
        values = result.image[..., 0]
        error = np.sqrt(result.variance[..., 0].sum()) / values.size
        exact = furnace_radiance(albedo, 1.0)
        assert error < 1e-3 * exact * 1.5
        assert abs(values.mean() - exact) < 3 * error


def test_undersampled_blocks_are_reported():
    rng = np.random.default_rng(3)
    a, va, b, vb = noisy_pair(rng, samples=64)
    b[0:8, 0:8, 0] = 0.0   # an estimator that found nothing in one block...
    vb[0:8, 0:8, 0] = 0.0  # ... and so reports no variance there
    result = compare_estimates(a, va, b, vb)
    assert result.undersampled == 1 and "undersampled" in str(result)
