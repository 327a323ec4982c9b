"""Error metrics between a test image and a reference (both linear, same shape).

relMSE follows Rousselle et al. and pbrt-v4's ``imgtool diff``:
mean((x - r)^2 / (r^2 + epsilon)) with epsilon = 0.01, which keeps dark
reference pixels from dominating.
"""
from __future__ import annotations

import numpy as np

__all__ = ["mse", "rmse", "relmse", "compare"]

RELMSE_EPSILON = 0.01


def _pair(test: np.ndarray, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    test = np.asarray(test, dtype=np.float64)
    reference = np.asarray(reference, dtype=np.float64)
    if test.shape != reference.shape:
        raise ValueError(f"images differ in shape: test {test.shape}, reference {reference.shape}")
    if not (np.all(np.isfinite(test)) and np.all(np.isfinite(reference))):
        raise ValueError("images contain NaN or Inf values")
    return test, reference


def mse(test: np.ndarray, reference: np.ndarray) -> float:
    """Mean squared error over all pixels and channels."""
    test, reference = _pair(test, reference)
    return float(np.mean((test - reference) ** 2))


def rmse(test: np.ndarray, reference: np.ndarray) -> float:
    """Root mean squared error."""
    return float(np.sqrt(mse(test, reference)))


def relmse(test: np.ndarray, reference: np.ndarray, epsilon: float = RELMSE_EPSILON) -> float:
    """Relative MSE: mean((x - r)^2 / (r^2 + epsilon))."""
    test, reference = _pair(test, reference)
    return float(np.mean((test - reference) ** 2 / (reference ** 2 + epsilon)))


def compare(test: np.ndarray, reference: np.ndarray) -> dict[str, float]:
    """All metrics as a dict: mse, rmse, relmse."""
    return {"mse": mse(test, reference), "rmse": rmse(test, reference), "relmse": relmse(test, reference)}
