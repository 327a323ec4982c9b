"""Error metrics of a test image against a reference, and the error a render predicts for itself.

Both images are linear RGB (height, width, 3) of the same shape; every
metric is a mean over pixels and channels:

``mse``     mean (x - r)^2
``rmse``    sqrt(mse)
``relmse``  mean (x - r)^2 / (r^2 + eps)  (Rousselle et al. 2011; pbrt-v4's ``imgtool diff``;
            eps = 0.01 keeps dark reference pixels from dominating)
``mape``    mean |x - r| / (|r| + eps)
``smape``   mean |x - r| / (|x| + |r| + eps), in [0, 1) (the symmetric form used in
            denoising papers, e.g. Vogels et al. 2018)
``flip``    NVIDIA's FLIP (Andersson et al. 2020, package ``flip-evaluator``), LDR-FLIP of the
            *display* images: both tone-mapped by :func:`pathspace.imageio.display` (exposure,
            clip to [0, 1], sRGB transfer function) -- what a viewer of the PNGs sees.

:func:`predicted_relmse` needs no reference: from a render's own variance
layer it gives the relMSE the render is expected to have, with a confidence
interval, so a run can be judged without a reference.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["METRICS", "RELMSE_EPSILON", "PredictedError", "compare", "flip", "mape", "mse", "predicted_relmse",
           "relmse", "rmse", "smape"]

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


def mape(test: np.ndarray, reference: np.ndarray, epsilon: float = RELMSE_EPSILON) -> float:
    """Mean absolute percentage error (as a fraction): mean(|x - r| / (|r| + epsilon))."""
    test, reference = _pair(test, reference)
    return float(np.mean(np.abs(test - reference) / (np.abs(reference) + epsilon)))


def smape(test: np.ndarray, reference: np.ndarray, epsilon: float = RELMSE_EPSILON) -> float:
    """Symmetric MAPE: mean(|x - r| / (|x| + |r| + epsilon)), in [0, 1)."""
    test, reference = _pair(test, reference)
    return float(np.mean(np.abs(test - reference) / (np.abs(test) + np.abs(reference) + epsilon)))


def flip(test: np.ndarray, reference: np.ndarray, exposure: float = 0.0, pixels_per_degree: float = 67.0) -> float:
    """Mean LDR-FLIP error between the display images (exposure in stops, clipped, sRGB-encoded) of
    ``test`` and ``reference``; 0 for identical images, up to 1.  Needs the ``experiments`` extra."""
    from .extras import optional_import
    from .imageio import display

    test, reference = _pair(test, reference)
    flip_evaluator = optional_import("flip_evaluator", "the FLIP metric (NVIDIA's flip-evaluator)")
    _, mean, _ = flip_evaluator.evaluate(np.ascontiguousarray(display(reference, exposure), dtype=np.float32),
                                         np.ascontiguousarray(display(test, exposure), dtype=np.float32), "LDR",
                                         inputsRGB=True, applyMagma=False, parameters={"ppd": pixels_per_degree})
    return float(mean)


METRICS: dict[str, Callable[[np.ndarray, np.ndarray], float]] = {
    "mse": mse, "rmse": rmse, "relmse": relmse, "mape": mape, "smape": smape, "flip": flip}


def compare(test: np.ndarray, reference: np.ndarray, metrics=("mse", "rmse", "relmse", "mape", "smape")
            ) -> dict[str, float]:
    """The named metrics (see :data:`METRICS`) as a dict."""
    unknown = [name for name in metrics if name not in METRICS]
    if unknown:
        raise ValueError(f"metrics: unknown {unknown}; known: {', '.join(METRICS)}")
    return {name: METRICS[name](test, reference) for name in metrics}


@dataclass
class PredictedError:
    """The relMSE a render expects from its own variance, with a ``confidence`` interval [low, high]."""

    relmse: float
    low: float
    high: float
    confidence: float

    def __str__(self) -> str:
        return f"predicted relMSE {self.relmse:.4g} ({self.confidence:.0%} interval {self.low:.4g} .. {self.high:.4g})"


def predicted_relmse(image: np.ndarray, variance: np.ndarray, samples: int | np.ndarray,
                     epsilon: float = RELMSE_EPSILON, confidence: float = 0.95) -> PredictedError:
    """The relMSE an unbiased render is expected to have against the exact image, from its own image, the
    variance of its per-pixel means, and the number of samples behind each.

    E[(x - r)^2] = Var(x) for an unbiased x; r^2 is estimated without bias by
    x^2 - Var(x).  The interval covers both the spread of the render's actual
    squared errors around their expectation and the uncertainty of the
    variance estimates (each from n samples), for normal errors that are
    independent between pixels but fully correlated between a pixel's
    channels; heavy-tailed samples (few samples, caustics) make it too narrow,
    and below ~16 samples the estimate itself runs high.
    """
    from scipy import stats

    x = np.asarray(image, dtype=np.float64)
    var = np.asarray(variance, dtype=np.float64)
    n = np.broadcast_to(np.asarray(samples, dtype=np.float64), x.shape[:2])[..., None]
    if not (np.all(np.isfinite(var)) and np.all(n >= 2)):
        raise ValueError("predicted_relmse needs a finite variance from at least 2 samples in every pixel")
    terms = var / (np.maximum(x * x - var, 0.0) + epsilon)
    estimate = float(terms.mean())
    per_pixel = terms.sum(axis=-1)
    spread = float(np.sqrt(np.sum(per_pixel ** 2 * 2.0 * (1.0 + 1.0 / (n[..., 0] - 1))))) / terms.size
    z = float(stats.norm.ppf(0.5 + confidence / 2))
    return PredictedError(estimate, max(estimate - z * spread, 0.0), estimate + z * spread, confidence)
