"""Images for studying strategies and errors: MIS-weight images, per-strategy variance, error images.

All functions take and return (height, width, 3) float arrays (linear RGB
unless said otherwise); :mod:`pathspace.plot` shows them.
"""
from __future__ import annotations

import numpy as np

from ..imageio import display
from ..metrics import RELMSE_EPSILON

__all__ = ["strategy_images", "weight_images", "difference", "relative_error", "z_scores", "posterize"]


def strategy_images(result) -> dict[tuple[int, int], dict[str, np.ndarray]]:
    """Per strategy (s, t) of a bidirectional render with ``pyramid`` > 0: the "unweighted" and "weighted"
    mean images, their variances ("unweighted_variance", "weighted_variance", from the passes), and the
    MIS "weight" image (weighted / unweighted where the strategy contributes, NaN elsewhere)."""
    film = result.film
    if not result.strategies:
        raise ValueError("no strategy images: render a bidirectional estimator with pyramid > 0")
    out = {}
    for key, images in result.strategies.items():
        s, t = key
        entry = dict(images)
        for kind in ("unweighted", "weighted"):
            entry[f"{kind}_variance"] = film.layer_variance(f"s{s}t{t}.{kind}", film.to_srgb)
        with np.errstate(divide="ignore", invalid="ignore"):
            entry["weight"] = np.where(images["unweighted"] != 0, images["weighted"] / images["unweighted"], np.nan)
        out[key] = entry
    return out


def weight_images(result) -> dict[tuple[int, int], np.ndarray]:
    """The MIS-weight image (weighted / unweighted mean) of every strategy of a pyramid render."""
    return {key: images["weight"] for key, images in strategy_images(result).items()}


def difference(test: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """test - reference."""
    return np.asarray(test, dtype=np.float64) - np.asarray(reference, dtype=np.float64)


def relative_error(test: np.ndarray, reference: np.ndarray, epsilon: float = RELMSE_EPSILON) -> np.ndarray:
    """(test - reference) / (|reference| + epsilon)."""
    reference = np.asarray(reference, dtype=np.float64)
    return difference(test, reference) / (np.abs(reference) + epsilon)


def z_scores(test: np.ndarray, test_variance: np.ndarray, reference: np.ndarray,
             reference_variance: np.ndarray | None = None) -> np.ndarray:
    """Per-pixel z = (test - reference) / sqrt(var_test + var_reference): about N(0, 1) where both estimate
    the same image (0 where both variances are 0 and the values agree, +-inf where they do not)."""
    var = np.asarray(test_variance, dtype=np.float64)
    if reference_variance is not None:
        var = var + np.asarray(reference_variance, dtype=np.float64)
    d = difference(test, reference)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(var > 0, d / np.sqrt(var), np.where(d == 0, 0.0, np.sign(d) * np.inf))


def posterize(image: np.ndarray, levels: int = 8, exposure: float = 0.0) -> np.ndarray:
    """The display image quantised to ``levels`` levels per channel (in [0, 1]): banding, clipping and a
    wrong normalisation show as steps in the wrong places."""
    if not (isinstance(levels, (int, np.integer)) and levels >= 2):
        raise ValueError(f"levels: expected an integer >= 2, got {levels!r}")
    return np.floor(display(image, exposure) * (levels - 1) + 0.5) / (levels - 1)
