"""The error metrics of a test image against a reference (hand-computed values), FLIP through the package's
wrapper, and the relMSE a render predicts for itself (coverage of its interval on synthetic renders whose
error is known)."""
from __future__ import annotations

import numpy as np
import pytest

from pathspace import metrics
from pathspace.imageio import display


def one_pixel_off():
    reference = np.full((2, 2, 3), 1.0)
    test = reference.copy()
    test[0, 0, 0] = 2.0
    return test, reference


def test_hand_computed_values():
    test, reference = one_pixel_off()
    assert metrics.mse(test, reference) == pytest.approx(1 / 12)
    assert metrics.rmse(test, reference) == pytest.approx(np.sqrt(1 / 12))
    assert metrics.relmse(test, reference) == pytest.approx(1 / 12 / 1.01)
    assert metrics.relmse(test, reference, epsilon=0.0) == pytest.approx(1 / 12)
    assert metrics.mape(test, reference) == pytest.approx(1 / 12 / 1.01)
    assert metrics.smape(test, reference) == pytest.approx(1 / 12 / 3.01)
    # A dark reference pixel: epsilon bounds its weight.
    assert metrics.relmse(np.full((1, 1, 1), 0.1), np.zeros((1, 1, 1))) == pytest.approx(0.01 / 0.01)
    assert metrics.compare(test, reference, ("mse", "smape")) == {"mse": pytest.approx(1 / 12),
                                                                  "smape": pytest.approx(1 / 12 / 3.01)}


def test_bad_inputs_are_named():
    test, reference = one_pixel_off()
    with pytest.raises(ValueError, match="differ in shape"):
        metrics.mse(test, reference[:1])
    with pytest.raises(ValueError, match="NaN or Inf"):
        metrics.relmse(np.where(test > 1.5, np.nan, test), reference)
    with pytest.raises(ValueError, match="unknown \\['psnr'\\]"):
        metrics.compare(test, reference, ("mse", "psnr"))


def test_flip_is_the_evaluator_on_the_display_images():
    flip_evaluator = pytest.importorskip("flip_evaluator", reason="the experiments extra is not installed")
    rng = np.random.default_rng(0)
    reference = rng.uniform(0.0, 1.5, (48, 64, 3))
    assert metrics.flip(reference, reference) == 0.0
    errors = []
    for sigma in (0.02, 0.1, 0.4):
        test = np.maximum(reference + rng.normal(0.0, sigma, reference.shape), 0.0)
        errors.append(metrics.flip(test, reference))
        _, direct, _ = flip_evaluator.evaluate(display(reference).astype(np.float32), display(test).astype(np.float32),
                                               "LDR", inputsRGB=True, applyMagma=False, parameters={"ppd": 67.0})
        assert errors[-1] == pytest.approx(direct, rel=1e-6)
    assert 0.0 < errors[0] < errors[1] < errors[2] < 1.0
    # Exposure is applied before display: one stop down on both images changes the error.
    assert metrics.flip(test, reference, exposure=-1.0) != pytest.approx(errors[2], rel=1e-3)


def test_predicted_relmse_covers_the_actual_error():
    """Synthetic renders: pixel means x = r + N(0, var/n), the variance estimated from n samples.  The
    predicted relMSE must match the actual one and its 95% interval must cover it about 95% of the time."""
    rng = np.random.default_rng(3)
    reference = rng.uniform(0.05, 2.0, (40, 40, 1)) * np.array([1.0, 0.7, 0.4])
    sample_sigma = 0.5 * reference
    n = 64
    covered, ratios = 0, []
    trials = 200
    for _ in range(trials):
        samples = reference + sample_sigma * rng.standard_normal((n, 40, 40, 1))  # channels correlated
        image = samples.mean(axis=0)
        variance_of_mean = samples.var(axis=0, ddof=1) / n
        predicted = metrics.predicted_relmse(image, variance_of_mean, n)
        actual = metrics.relmse(image, reference)
        covered += predicted.low <= actual <= predicted.high
        ratios.append(predicted.relmse / actual)
    assert 0.97 < np.mean(ratios) < 1.03, np.mean(ratios)
    assert 0.88 <= covered / trials <= 1.0, covered / trials
    with pytest.raises(ValueError, match="at least 2 samples"):
        metrics.predicted_relmse(image, variance_of_mean, 1)
