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

A render that raises marks its cell failed (column ``error``, :attr:`Sweep.failed`) and
the sweep goes on.  With a Dask ``client`` every cell and seed is a task on the cluster
(:mod:`pathspace.cluster`), and finished renders are cached
(:mod:`pathspace.experiment.cache`) so that a sweep run again renders only what it is missing.
"""
from __future__ import annotations

import itertools
import json
import os
from dataclasses import dataclass
from typing import Any, Callable, Iterator, Sequence

import numpy as np

from .._native import default_thread_count
from ..metrics import METRICS
from ..scene import load_scene
from ..validate import compare_estimates
from .cache import CellCache
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
        """The unbiased cell with the highest mean ``by`` (cells that failed are left out)."""
        candidates = self.cells[self.cells["biased"].eq(False) & self.cells["error"].isna()]
        return candidates.loc[candidates[by].idxmax()] if len(candidates) else None

    @property
    def failed(self):
        """The cells whose render raised, with the error (column ``error``)."""
        return self.cells[self.cells["error"].notna()]


def sweep(scene, estimator: Any, grid: dict[str, Sequence[Any]], reference: Any, *, spp: int | None = None,
          time: float | None = None, seeds: Sequence[int] = (0, 1), metrics: Sequence[str] = ("relmse", "mse"),
          alpha: float = 1e-3, block: int = 8, threads: int | None = None, progress: bool = False,
          client: Any = None, cache: Any = None, on_render: Callable[[dict], None] | None = None) -> Sweep:
    """Render ``estimator`` (a name, (name, fixed params) or spec) for every cell of ``grid`` and every seed,
    with ``spp`` samples per pixel or ``time`` seconds each; see the module docstring.

    Parameter values are checked before anything renders (a bad one raises).  A render that raises (the
    scene refuses the setting, a worker fails) marks its cell failed: its ``error`` column holds the
    message, and the other cells finish.  ``client``: a ``dask.distributed.Client``; every cell and seed
    is then a task rendering on one worker thread (see :mod:`pathspace.cluster`).  ``cache``: a folder,
    True, False, or None -- cache finished renders when on a cluster -- so that a sweep run again renders
    only what it is missing (:mod:`pathspace.experiment.cache`).  ``on_render(row)`` is called with each
    render's table row as it finishes (cached ones first), for watching a long sweep."""
    pd = pandas()
    if (time is None) == (spp is None):
        raise ValueError("give either time (seconds) or spp")
    if client is not None and threads is not None:
        raise ValueError("threads: cells on a cluster render on one worker thread each")
    seeds = list(seeds)
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds: expected distinct seeds, got {seeds}")
    spec = EstimatorSpec.parse(estimator)
    ref, ref_variance = reference_image(reference)
    if ref_variance is None:
        ref_variance = np.zeros_like(ref)
    cells = grid_cells(grid)
    estimators = [spec.make(**cell) for cell in cells]  # parameter errors surface here, before any render
    if isinstance(scene, (str, os.PathLike)):
        scene = load_scene(scene)
    store = CellCache.choose(cache, client is not None)
    jobs = [(c, seed) for c in range(len(cells)) for seed in seeds]
    render_threads = 1 if client is not None else (default_thread_count() if threads is None else threads)
    keys = ({job: store.key(scene, estimators[job[0]], job[1], spp, time, render_threads) for job in jobs}
            if store else {})
    outcomes, job_rows, summaries = {}, {}, {}

    def finished(job: tuple[int, int], outcome) -> None:
        """Tabulate a finished render; pool its cell once every seed is in (then its images are let go)."""
        outcomes[job] = outcome
        if not isinstance(outcome, BaseException):
            job_rows[job] = {**cells[job[0]], "seed": job[1], **_row(outcome, ref, metrics)}
            if on_render is not None:
                on_render(job_rows[job])
        c = job[0]
        if all((c, seed) in outcomes for seed in seeds):
            renders = [(seed, outcomes.pop((c, seed))) for seed in seeds]
            summaries[c] = _summary(cells[c], renders, [job_rows[(c, seed)] for seed, r in renders
                                                        if not isinstance(r, BaseException)],
                                    ref, ref_variance, alpha, block, metrics, estimators[c].independent_passes)

    for job in jobs:
        cached = store.get(keys[job]) if store else None
        if cached is not None:
            finished(job, cached)
    missing = [job for job in jobs if job not in job_rows]
    for job, outcome in _renders(scene, estimators, missing, spp, time, threads, progress, client):
        if store and not isinstance(outcome, BaseException):
            store.put(keys[job], outcome)
        finished(job, outcome)
    table = pd.DataFrame([job_rows[job] for job in jobs if job in job_rows])
    summary_table = pd.DataFrame([summaries[c] for c in range(len(cells))])
    for frame in (table, summary_table):
        frame.insert(0, "estimator", spec.label)
        frame.insert(1, "fixed", json.dumps(spec.params, sort_keys=True, default=str))
    return Sweep(table, summary_table, tuple(grid))


def _summary(cell: dict, renders: list[tuple[int, Any]], rows: list[dict], reference: np.ndarray,
             reference_variance: np.ndarray, alpha: float, block: int, metrics: Sequence[str],
             independent: bool) -> dict:
    """A cell's line of the summary from its renders ((seed, render or the exception it raised)) and their
    table ``rows``: the pooled test against the reference, the mean of each statistic, the warnings, and
    the errors of failed renders (``error``; None if every render finished)."""
    errors = [f"seed {seed}: {type(r).__name__}: {r}" for seed, r in renders if isinstance(r, BaseException)]
    results = [r for _, r in renders if not isinstance(r, BaseException)]
    summary = {**cell, "error": "; ".join(errors) if errors else None}
    if not results:
        return {**summary, "biased": None, "warnings": []}
    means = pandas().DataFrame(rows)[["efficiency", "inverse_variance_time", "variance_per_sample",
                                      "time_per_sample", *metrics]].mean()
    return {**summary, **_pooled(results, reference, reference_variance, alpha, block, independent=independent),
            **means.to_dict(), "warnings": sorted({w for r in results for w in r.stats["warnings"]})}


def _renders(scene, estimators: list, jobs: list[tuple[int, int]], spp: int | None, seconds: float | None,
             threads: int | None, progress: bool, client: Any) -> Iterator[tuple[tuple[int, int], Any]]:
    """((cell, seed), render or the exception it raised) for every job, as each finishes: in this process,
    one after the other, or as tasks on ``client``'s cluster."""
    if not jobs:
        return
    if client is not None:
        from ..cluster.tasks import render_cell
        from ..cluster.work import run_tasks

        tasks = [dict(estimator=estimators[c], seed=seed) for c, seed in jobs]
        for index, outcome in run_tasks(client, scene, render_cell, tasks, shared=dict(spp=spp, seconds=seconds),
                                        progress=progress, unit="cell"):
            yield jobs[index], outcome
        return
    from ..driver import render

    for c, seed in jobs:
        try:
            outcome = render(scene, estimators[c], spp=spp, time=seconds, seed=seed, threads=threads,
                             progress=progress)
        except Exception as error:  # the cell fails, the sweep goes on
            outcome = error
        yield (c, seed), outcome


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
