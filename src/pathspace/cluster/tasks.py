"""What runs on a worker: the tasks of renders, sweeps and convergence runs.

Each task gets its scene as a :class:`~pathspace.cluster.scenes.ScenePayload` (unpickled once per
worker process) and renders on one thread of the worker; its result is small enough to send back:
a film (renders), an image with its variance and statistics (sweep cells), or table rows (convergence).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..estimators.base import Counters
from ..film import Film
from .scenes import ScenePayload, scene_on_worker

__all__ = ["PassesResult", "CellResult", "render_passes", "render_cell", "converge_run"]


@dataclass
class PassesResult:
    """The passes of one render task: their ``film``, what the render counted, its render ``seconds`` and the
    ``worker`` that rendered them."""

    film: Film
    counters: Counters
    seconds: float
    worker: str


@dataclass
class CellResult:
    """One render of a sweep cell: what :func:`pathspace.experiment.sweep` tabulates (``image``,
    ``variance``, ``stats``)."""

    image: np.ndarray
    variance: np.ndarray
    stats: dict


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):  # called outside a worker (tests, in-process runs)
        return "local"


def render_passes(payload: ScenePayload, estimator, seed: int, first_pass: int, spp: int, spectral: bool | None,
                  wavelength_sampling: str) -> PassesResult:
    """Passes ``first_pass`` .. ``first_pass + spp - 1`` of the render with ``seed``, on one thread."""
    from ..driver import render

    scene = scene_on_worker(payload)
    result = render(scene, estimator, spp=spp, seed=seed, first_pass=first_pass, threads=1, spectral=spectral,
                    wavelength_sampling=wavelength_sampling)
    s = result.stats
    counters = Counters(rays=s["rays"], truncated=s["truncated"], longest=s["longest_subpath"],
                        nonfinite_contributions=s["nonfinite_contributions"])
    return PassesResult(result.film, counters, s["seconds"], _worker_name())


def render_cell(payload: ScenePayload, estimator, seed: int, spp: int | None, seconds: float | None) -> CellResult:
    """One sweep render: ``estimator`` with ``seed`` for ``spp`` passes or ``seconds``, on one thread."""
    from ..driver import render

    result = render(scene_on_worker(payload), estimator, spp=spp, time=seconds, seed=seed, threads=1)
    stats = {k: v for k, v in result.stats.items() if k != "plan"}
    return CellResult(result.image, result.variance, stats)


def converge_run(payload: ScenePayload, spec, seed: int, reference: np.ndarray, spp: int | None,
                 seconds: float | None, checkpoints: list[float], metrics: tuple[str, ...],
                 keep_images: bool) -> tuple[list[dict], dict[Any, np.ndarray]]:
    """One convergence run (see :func:`pathspace.experiment.converge`) on one thread: its table rows and
    kept images."""
    from ..experiment.convergence import run_with_snapshots

    return run_with_snapshots(scene_on_worker(payload), spec, seed, reference, spp=spp, seconds=seconds,
                              checkpoints=checkpoints, metrics=metrics, keep_images=keep_images, threads=1)
