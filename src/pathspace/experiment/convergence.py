"""Error against run time from one run per estimator and seed: the convergence curves of a comparison.

Each estimator runs once per seed and is developed at checkpoints (seconds or
samples per pixel, log-spaced by default) -- never restarted per budget.  At
each checkpoint the film is developed, every metric computed against the
reference, and the error the render predicts for itself recorded; the clock
is paused meanwhile (see :mod:`pathspace.estimators.control`), so the
seconds in the table are render time only (scene loading and BVH builds are
excluded too), and the time spent on snapshots is reported beside them.
"""
from __future__ import annotations

import json
import time as _time
import warnings
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ..extras import optional_import
from ..metrics import METRICS, predicted_relmse
from .specs import EstimatorSpec

__all__ = ["Convergence", "converge", "default_checkpoints", "reference_image", "pandas"]

DEFAULT_METRICS = ("relmse", "mse", "mape", "smape")


def pandas():
    """The pandas module, or an ImportError saying how to install it."""
    return optional_import("pandas", "experiment tables")


def reference_image(reference: Any) -> tuple[np.ndarray, np.ndarray | None]:
    """(image, variance or None) of a reference: a :class:`~pathspace.reference.Reference`, a render result,
    or an (H, W, 3) array."""
    if hasattr(reference, "image"):
        return np.asarray(reference.image, dtype=np.float64), getattr(reference, "variance", None)
    return np.asarray(reference, dtype=np.float64), None


def default_checkpoints(spp: int | None, seconds: float | None, count: int = 7) -> list[float]:
    """Log-spaced checkpoints before the end of a budget (the end itself is always recorded)."""
    if seconds is not None:
        return [float(t) for t in np.geomspace(seconds / 2 ** (count - 1), seconds, count)[:-1]]
    points = np.unique(np.round(np.geomspace(1, spp, count + 1)).astype(int))
    return [int(p) for p in points if p < spp]


@dataclass
class Convergence:
    """The tidy table of a convergence study (one row per estimator, seed and checkpoint) and its views."""

    table: Any
    metrics: tuple[str, ...]
    images: dict = field(default_factory=dict, repr=False)

    def slopes(self, metric: str = "relmse", x: str = "seconds", start: float = 0.1):
        """Per estimator: the fitted slope of log(metric) against log(x), mean and standard error over seeds
        (-1 is the Monte Carlo rate of an unbiased estimator), over the snapshots past ``start`` of each run
        (its first tenth is dominated by start-up: threads, the first items in flight)."""
        pd = pandas()
        rows = []
        for (label, seed), run in self.table.groupby(["estimator", "seed"], sort=False):
            ok = (run[metric] > 0) & (run[x] > 0) & (run[x] >= start * run[x].max())
            if ok.sum() >= 2:
                rows.append({"estimator": label, "seed": seed,
                             "slope": np.polyfit(np.log(run[x][ok]), np.log(run[metric][ok]), 1)[0]})
        return _mean_over_seeds(pd.DataFrame(rows), "slope")

    def at(self, seconds: float | None = None, spp: float | None = None, metric: str = "relmse"):
        """Equal-time (``seconds``) or equal-spp (``spp``) comparison: each run's metric interpolated on its
        log-log curve at that point; mean and standard error over seeds, per estimator.  Runs whose curve
        does not reach the point are left out, with a warning (a time-budgeted run ends with its last whole
        work item, which may be before its budget: compare at a time every run reached)."""
        if (seconds is None) == (spp is None):
            raise ValueError("give either seconds or spp")
        x, where = ("seconds", seconds) if seconds is not None else ("spp", spp)
        if not where > 0:
            raise ValueError(f"{x}: expected a number > 0 (the curves are interpolated in log-log), got {where!r}")
        pd = pandas()
        rows, short = [], []
        for (label, seed), run in self.table.groupby(["estimator", "seed"], sort=False):
            run = run[(run["spp"] > 0) & (run[x] > 0)].sort_values(x)   # no curve before a run's first pass
            if run.empty or where < run[x].iloc[0] or where > run[x].iloc[-1]:
                if not run.empty and where > run[x].iloc[-1]:
                    short.append(f"{label} seed {seed} ({run[x].iloc[-1]:.4g})")
                continue  # outside the run: no extrapolation
            value = np.exp(np.interp(np.log(where), np.log(run[x]), np.log(np.maximum(run[metric], 1e-300))))
            rows.append({"estimator": label, "seed": seed, metric: value})
        if short:
            warnings.warn(f"at({x}={where:g}): left out {len(short)} run(s) that ended before it: {', '.join(short)}",
                          stacklevel=2)
        return _mean_over_seeds(pd.DataFrame(rows, columns=["estimator", "seed", metric]), metric)

    def efficiency(self, metric: str = "relmse"):
        """Per estimator: 1 / (metric x seconds) at the end of each run (mean and standard error over seeds):
        how much error-reduction a second buys; higher is better."""
        pd = pandas()
        final = self.table[self.table["final"]].copy()
        final["efficiency"] = 1.0 / (final[metric] * final["seconds"])
        return _mean_over_seeds(pd.DataFrame(final[["estimator", "seed", "efficiency"]]), "efficiency")

    def summary(self, metric: str = "relmse"):
        """One row per estimator: spp and seconds at the end, the final metric, slope and efficiency."""
        final = self.table[self.table["final"]].groupby("estimator", sort=False).agg(
            spp=("spp", "mean"), seconds=("seconds", "mean"), **{metric: (metric, "mean")},
            overhead_seconds=("overhead_seconds", "mean"))
        return final.join(self.slopes(metric)[["slope"]]).join(self.efficiency(metric)[["efficiency"]])

    def plot(self, metric: str = "relmse", x: str = "seconds", ax=None):
        """Log-log curves of ``metric`` against ``x``, one per estimator (seeds as a band), with fitted slopes."""
        from ..plot import convergence_plot

        return convergence_plot(self, metric, x, ax)

    def to_csv(self, path) -> None:
        """Write the table."""
        self.table.to_csv(path, index=False)


def _mean_over_seeds(frame, column: str):
    grouped = frame.groupby("estimator", sort=False)[column]
    out = grouped.mean().to_frame(column)
    out[f"{column}_error"] = grouped.sem().fillna(0.0) if len(frame) else []
    return out


def converge(scene, estimators: Sequence[Any], reference: Any, *, time: float | None = None, spp: int | None = None,
             checkpoints: Sequence[float] | None = None, seeds: Sequence[int] = (0,),
             metrics: Sequence[str] = DEFAULT_METRICS, threads: int | None = None, keep_images: bool = False,
             progress: bool = False, client: Any = None) -> Convergence:
    """Run every estimator (names, (name, params) pairs or :class:`EstimatorSpec` s) once per seed on
    ``scene`` for ``time`` seconds or ``spp`` samples per pixel, developing the film at ``checkpoints``
    (default: log-spaced) and at the end, and compare each snapshot with ``reference``.

    ``client``: a ``dask.distributed.Client``; every run (estimator and seed) is then a task rendering on
    one worker thread, and the runs go on side by side (see :mod:`pathspace.cluster`).  A run that raises
    stops the study (its error names the run); runs are not cached (sweeps' renders are)."""
    pd = pandas()
    if (time is None) == (spp is None):
        raise ValueError("give either time (seconds) or spp")
    unknown = [m for m in metrics if m not in METRICS]
    if unknown:
        raise ValueError(f"metrics: unknown {unknown}; known: {', '.join(METRICS)}")
    specs = [EstimatorSpec.parse(e) for e in estimators]
    for spec in specs:
        spec.make()  # parameter errors surface here, before any render
    ref, _ = reference_image(reference)
    points = list(checkpoints) if checkpoints is not None else default_checkpoints(spp, time)
    runs = [(spec, seed) for spec in specs for seed in seeds]
    if client is not None:
        from ..cluster.tasks import converge_run
        from ..cluster.work import run_tasks

        if threads is not None:
            raise ValueError("threads: runs on a cluster render on one worker thread each")
        outputs = [None] * len(runs)
        for index, output in run_tasks(client, scene, converge_run, [dict(spec=spec, seed=seed) for spec, seed in runs],
                                       shared=dict(reference=ref, spp=spp, seconds=time, checkpoints=points,
                                                   metrics=tuple(metrics), keep_images=keep_images),
                                       progress=progress, unit="run"):
            if isinstance(output, BaseException):
                spec, seed = runs[index]
                output.add_note(f"in the convergence run of {spec.label}, seed {seed}, on the cluster")
                raise output
            outputs[index] = output
    else:
        outputs = [run_with_snapshots(scene, spec, seed, ref, spp=spp, seconds=time, checkpoints=points,
                                      metrics=tuple(metrics), keep_images=keep_images, threads=threads,
                                      progress=progress) for spec, seed in runs]
    rows: list[dict] = []
    images: dict = {}
    for run_rows, run_images in outputs:
        rows += run_rows
        images.update(run_images)
    return Convergence(pd.DataFrame(rows), tuple(metrics), images)


def run_with_snapshots(scene, spec: EstimatorSpec, seed: int, reference: np.ndarray, *, spp: int | None,
                       seconds: float | None, checkpoints: Sequence[float], metrics: tuple[str, ...],
                       keep_images: bool, threads: int | None = None,
                       progress: bool = False) -> tuple[list[dict], dict]:
    """One convergence run: ``spec`` with ``seed`` for ``spp`` passes or ``seconds``, a table row per
    checkpoint and at the end; (rows, kept images)."""
    from ..driver import render

    snapshot = _Snapshots(spec, seed, reference, metrics, keep_images)
    result = render(scene, spec.make(), spp=spp, time=seconds, seed=seed, threads=threads, progress=progress,
                    checkpoints=checkpoints, on_checkpoint=snapshot)
    snapshot.record(result.film, result.stats["seconds"], final=True)
    return snapshot.rows, snapshot.images


class _Snapshots:
    """The on_checkpoint of one run: one table row per snapshot, the time spent on them counted."""

    def __init__(self, spec: EstimatorSpec, seed: int, reference: np.ndarray, metrics: tuple[str, ...],
                 keep_images: bool) -> None:
        self.spec, self.seed, self.reference, self.metrics, self.keep = spec, seed, reference, metrics, keep_images
        self.independent_passes = spec.make().independent_passes   # else the film's variance is not the error
        self.rows: list[dict] = []
        self.images: dict = {}
        self.overhead = 0.0

    def __call__(self, checkpoint) -> None:
        self.record(checkpoint.film, checkpoint.seconds, final=False)

    def record(self, film, seconds: float, final: bool) -> None:
        start = _time.perf_counter()
        image = film.image()
        row = {"estimator": self.spec.label, "name": self.spec.name,
               "params": json.dumps(self.spec.params, sort_keys=True, default=str), "seed": self.seed,
               "spp": film.passes, "seconds": seconds, "final": final}
        for name in self.metrics:
            row[name] = METRICS[name](image, self.reference)
        if film.count.min() >= 2 and self.independent_passes:
            predicted = predicted_relmse(image, film.image_variance(), film.count.reshape(film.height, film.width))
            row.update(predicted_relmse=predicted.relmse, predicted_low=predicted.low, predicted_high=predicted.high)
        if self.keep:
            self.images[(self.spec.label, self.seed, film.passes)] = image
        self.overhead += _time.perf_counter() - start
        row["overhead_seconds"] = self.overhead
        self.rows.append(row)
