"""The estimator comparison (pathspace.validate.compare): calibrated on noise (false alarms at about alpha),
sensitive to small global and local biases, input checks, undersampled blocks reported.  Its use on real
renders -- and its power to catch a wrong pdf or a truncated path length there -- is in
tests/estimators/test_agreement.py."""
from __future__ import annotations

import numpy as np
import pytest

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


def test_undersampled_blocks_are_reported():
    rng = np.random.default_rng(3)
    a, va, b, vb = noisy_pair(rng, samples=64)
    b[0:8, 0:8, 0] = 0.0   # an estimator that found nothing in one block...
    vb[0:8, 0:8, 0] = 0.0  # ... and so reports no variance there
    result = compare_estimates(a, va, b, vb)
    assert result.undersampled == 1 and "undersampled" in str(result)

