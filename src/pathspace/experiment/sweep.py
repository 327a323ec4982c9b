"""Sweeps: one estimator over a grid of parameter settings, at equal time or equal spp, several seeds.

Every cell of the grid (the cartesian product of the values given per
parameter) renders once per seed.  The tidy table has one row per cell and
seed: the parameters, spp, seconds, the image mean and its standard error,
the variance per sample, the time per sample, every metric against the
reference and the efficiencies 1 / (relMSE x seconds) and
1 / (variance per sample x time per sample).  Per cell (:attr:`Sweep.cells`)
the seeds are pooled and the pooled image's mean is compared with the
reference's: a setting whose mean disagrees with the reference beyond its
error (|z| above the two-sided critical value at ``alpha``) is flagged
``biased`` -- a biased setting stays visible instead of being averaged away.
The block-wise z-test of the pooled image (:func:`pathspace.validate.compare_estimates`)
is reported beside it (``blocks_agree``, ``max_abs_z``): it also sees a bias
confined to a region, but it trusts every block's variance estimate, which
heavy-tailed estimators (caustics by path tracing at few samples) get wrong,
so it is information, not the flag.  The estimator's and the renders'
warnings (infinite-variance roulette, ...) are collected per cell.
Markov-chain estimators (MLT) report no per-render variance (their passes
are correlated) and their pixels are correlated too (the bootstrap's
brightness scales a whole render): their pooled error is the spread of the
seeds' image means (and block means), tested with Student-t quantiles of
seeds - 1 degrees of freedom (two seeds or more; with one, the cell is not
tested; with few seeds the test is weak but keeps its false-alarm rate), and
their per-render variance columns are NaN.
"""
from __future__ import annotations

import itertools
import json
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..metrics import METRICS
from ..validate import compare_estimates
from .convergence import pandas, reference_image
from .specs import EstimatorSpec

__all__ = ["Sweep", "sweep", "grid_cells"]


def grid_cells(grid: dict[str, Sequence[Any]]) -> list[dict[str, Any]]:
    """Every combination of the values of ``grid`` ({parameter: values}), in order."""
    names = list(grid)
    return [dict(zip(names, values)) for values in itertools.product(*(grid[n] for n in names))]


@dataclass
class Sweep:
    """A sweep's tidy table (one row per cell and seed) and its per-cell summary with bias flags."""

    table: Any
    cells: Any
    parameters: tuple[str, ...]

    def best(self, by: str = "efficiency"):
        """The unbiased cell with the highest mean ``by``."""
        candidates = self.cells[~self.cells["biased"]]
        return candidates.loc[candidates[by].idxmax()] if len(candidates) else None


def sweep(scene, estimator: Any, grid: dict[str, Sequence[Any]], reference: Any, *, spp: int | None = None,
          time: float | None = None, seeds: Sequence[int] = (0, 1), metrics: Sequence[str] = ("relmse", "mse"),
          alpha: float = 1e-3, block: int = 8, threads: int | None = None, progress: bool = False) -> Sweep:
    """Render ``estimator`` (a name, (name, fixed params) or spec) for every cell of ``grid`` and every seed,
    with ``spp`` samples per pixel or ``time`` seconds each; see the module docstring."""
    from ..driver import render

    pd = pandas()
    if (time is None) == (spp is None):
        raise ValueError("give either time (seconds) or spp")
    spec = EstimatorSpec.parse(estimator)
    ref, ref_variance = reference_image(reference)
    if ref_variance is None:
        ref_variance = np.zeros_like(ref)
    rows, cells = [], []
    for cell in grid_cells(grid):
        estimator_instance = spec.make(**cell)  # parameter errors surface here, before any render
        results = []
        for seed in seeds:
            result = render(scene, estimator_instance, spp=spp, time=time, seed=seed, threads=threads,
                            progress=progress)
            results.append(result)
            rows.append({**cell, "seed": seed, **_row(result, ref, metrics)})
        warnings = sorted({w for r in results for w in r.stats["warnings"]})
        means = pd.DataFrame(rows[-len(seeds):])[["efficiency", "inverse_variance_time", "variance_per_sample",
                                                 "time_per_sample", *metrics]].mean()
        cells.append({**cell, **_pooled(results, ref, ref_variance, alpha, block,
                                        independent=estimator_instance.independent_passes), **means.to_dict(),
                      "warnings": warnings})
    table = pd.DataFrame(rows)
    summary = pd.DataFrame(cells)
    for frame in (table, summary):
        frame.insert(0, "estimator", spec.label)
        frame.insert(1, "fixed", json.dumps(spec.params, sort_keys=True, default=str))
    return Sweep(table, summary, tuple(grid))


def _row(result, reference: np.ndarray, metrics: Sequence[str]) -> dict:
    """The statistics of one render."""
    image, variance, stats = result.image, result.variance, result.stats
    pixels = image.shape[0] * image.shape[1]
    passes = max(stats["spp"], 1)
    variance_per_sample = float(np.mean(variance) * passes)
    time_per_sample = stats["seconds"] / (passes * pixels)
    row = {"spp": stats["spp"], "seconds": stats["seconds"], "mean": float(image.mean()),
           "mean_error": float(np.sqrt(variance.sum()) / variance.size),
           "variance_per_sample": variance_per_sample, "time_per_sample": time_per_sample,
           "inverse_variance_time": 1.0 / (variance_per_sample * time_per_sample)}
    row.update({name: METRICS[name](image, reference) for name in metrics})
    row["efficiency"] = 1.0 / (METRICS["relmse"](image, reference) * stats["seconds"])
    return row


def _pooled(results: list, reference: np.ndarray, reference_variance: np.ndarray, alpha: float, block: int,
            independent: bool | None = None) -> dict:
    """The seeds of a cell pooled into one estimate, tested against the reference.  ``independent``: the
    estimator's passes are independent (its renders' variances are their errors); None: the renders with a
    NaN variance everywhere are Markov chains."""
    from scipy import stats

    if independent is None:
        independent = not all(np.isnan(r.variance).all() for r in results)
    if not independent:
        return _pooled_over_seeds(np.stack([r.image for r in results]), reference, reference_variance, alpha, block)
    image = np.mean([r.image for r in results], axis=0)
    variance = np.mean([r.variance for r in results], axis=0) / len(results)
    if not np.isfinite(variance).all():
        return _untested(image, reference)
    blocks = compare_estimates(image, variance, reference, reference_variance, block=block, alpha=alpha)
    error = np.sqrt(variance.sum() + reference_variance.sum()) / image.size
    difference = image.mean() - reference.mean()
    z = float(difference / error) if error > 0 else (0.0 if difference == 0 else float(np.sign(difference) * np.inf))
    return {"pooled_mean": float(image.mean()), "reference_mean": float(reference.mean()), "mean_z": z,
            "biased": bool(abs(z) > stats.norm.isf(alpha / 2)), "blocks_agree": bool(blocks.passed),
            "max_abs_z": float(blocks.max_abs_z)}


def _untested(image: np.ndarray, reference: np.ndarray) -> dict:
    return {"pooled_mean": float(image.mean()), "reference_mean": float(reference.mean()), "mean_z": np.nan,
            "biased": None, "blocks_agree": None, "max_abs_z": np.nan}


def _pooled_over_seeds(images: np.ndarray, reference: np.ndarray, reference_variance: np.ndarray, alpha: float,
                       block: int) -> dict:
    """Markov-chain renders (S, H, W, C), one per seed, pooled and tested against the reference.

    Their pixels are not independent (the bootstrap's error in the brightness b scales every pixel of a
    render together), so the error of the image mean is not the sum of per-pixel variances: it is the
    spread of the S per-seed image means (and per block, of the per-seed block means), with S - 1 degrees
    of freedom.  Each difference d with seed variance v (of the mean over seeds, S - 1 degrees of freedom)
    and reference variance r (taken as exact) is a Student t = d / sqrt(v + r) with Welch-Satterthwaite
    degrees of freedom (S - 1) (1 + r / v)^2 (S - 1 when r = 0).  The statistics reported (``mean_z``,
    ``max_abs_z``) are its normal equivalents, z with the same two-sided p-value, so the flags are at
    level ``alpha`` like the independent estimators'.  The blocks' test is the largest |z| against the
    Sidak-corrected critical value (conservative for correlated blocks); the chi-square of every block,
    which needs independent blocks, is not used.  One seed: no error estimate, untested.
    """
    from scipy import stats

    from ..validate import sidak_significance
    from ..validate.compare import _blocks

    count = len(images)
    image = images.mean(axis=0)
    if count < 2 or not np.isfinite(images).all():
        return _untested(image, reference)
    h, w = image.shape[:2]
    if block < 1 or block > min(h, w):
        raise ValueError(f"block must lie in [1, {min(h, w)}], got {block}")

    def normal_equivalent(difference, seed_variance, reference_variance):
        difference, v, r = np.broadcast_arrays(*(np.asarray(x, np.float64) for x in
                                                 (difference, seed_variance, reference_variance)))
        error = np.sqrt(v + r)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(error > 0, difference / error, np.where(difference == 0, 0.0, np.sign(difference) * np.inf))
            dof = np.where(v > 0, (count - 1) * (1.0 + r / v) ** 2, np.inf)
        p = stats.t.sf(np.abs(t), dof)       # one-sided; stats.t with infinite dof is the normal
        return np.sign(t) * stats.norm.isf(p)

    means = images.mean(axis=(1, 2, 3))
    z = float(normal_equivalent(means.mean() - reference.mean(), means.var(ddof=1) / count,
                                reference_variance.sum() / reference.size ** 2))
    per_seed = np.stack([_blocks(np.asarray(x, np.float64), block) for x in images])
    block_z = normal_equivalent(per_seed.mean(axis=0) - _blocks(np.asarray(reference, np.float64), block),
                                per_seed.var(axis=0, ddof=1) / count,
                                _blocks(np.asarray(reference_variance, np.float64), block) / block ** 2)
    max_abs_z = float(np.abs(block_z).max())
    critical = stats.norm.isf(sidak_significance(alpha, block_z.size) / 2)
    return {"pooled_mean": float(image.mean()), "reference_mean": float(reference.mean()), "mean_z": z,
            "biased": bool(abs(z) > stats.norm.isf(alpha / 2)), "blocks_agree": bool(max_abs_z < critical),
            "max_abs_z": max_abs_z}
