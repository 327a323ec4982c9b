"""One render on a cluster: its passes as tasks, their films merged in pass order as they arrive.

The render of ``spp`` passes from ``first_pass`` is cut into tasks of ``task_passes`` consecutive
passes.  Task k renders its passes with the render's seed and ``first_pass`` = its first pass: the
random streams of a (pass, tile) unit depend on the seed and the pass only, and the tiles of an image
do not depend on the pass count (:func:`pathspace.estimators.passes.work_layout`), so a task's samples
are those of the same passes in one process.  Its film joins the client's film by
:meth:`pathspace.film.Film.merge` in task order, whatever order the tasks finish in: the image equals
the single-process render's to rounding (Chan's pairwise update against Welford's one sample at a
time; a few ulps) and two cluster renders with the same ``task_passes`` are bit for bit equal, on any
number of workers.

At most ``2 x worker threads`` tasks are outstanding (submitted and not yet merged; workers that join
during the render widen the window), and the film of a task that finished before the ones ahead of it
stays on its worker until its turn: the client holds its own film and one task's.  A task whose worker
dies is run again by Dask on another worker (``distributed.scheduler.allowed-failures``, default 3);
if the scene was lost with it, the render ships it again and submits the tasks that needed it again
(:class:`~pathspace.cluster.scenes.Shipments`).  Each task is merged once, by its index.  A task that
raises cancels the render and re-raises its error, with a note naming its passes.
"""
from __future__ import annotations

import time
import uuid
from dataclasses import dataclass, field

from ..estimators.base import Counters
from ..film import Film
from ..progress import progress_bar
from .client import require_distributed
from .scenes import ScenePayload, Shipments
from .tasks import render_passes

__all__ = ["ClusterRun", "render_on_cluster", "default_task_passes", "TASKS_PER_THREAD"]

# How often a render asks the scheduler for the workers' threads (each question is a round trip).
WORKER_RECOUNT_SECONDS = 1.0
# Tasks per worker thread when task_passes is not given: enough that an uneven last round costs little
# (two workers, 64 spp at 256x256: 1.74-1.78x one worker's rate with 4, 1.87-1.90x with 8 per thread,
# the overhead of a task being about 6 ms).
TASKS_PER_THREAD = 8


@dataclass
class ClusterRun:
    """What a render on a cluster gives the driver: the merged ``film``, the tasks' summed ``counters``,
    the wall ``seconds`` from the first submission to the last merge, the worker ``threads`` and the
    ``stats`` it adds: ``stats["cluster"]`` = {scheduler, threads, workers_used, tasks, task_passes,
    task_seconds (their render time, summed), tasks_waiting_peak (the most finished tasks at once whose
    films waited on the workers for their turn, the next one to merge included), scene_reships (how many
    times the scene was shipped again after the cluster lost it)}."""

    film: Film
    counters: Counters
    seconds: float
    threads: int
    stats: dict = field(default_factory=dict)


def default_task_passes(spp: int, threads: int) -> int:
    """Passes per task: about TASKS_PER_THREAD tasks per worker thread."""
    return max(1, -(-spp // (TASKS_PER_THREAD * threads)))


def worker_threads(client, timeout: float = 60.0) -> int:
    """The worker threads of ``client``'s cluster, waiting up to ``timeout`` seconds for a first worker."""
    threads = sum(client.nthreads().values())
    if not threads:
        client.wait_for_workers(1, timeout=timeout)
        threads = sum(client.nthreads().values())
    return threads


def render_on_cluster(client, scene, estimator, mode, *, spp: int, seed: int, first_pass: int,
                      spectral: bool | None, wavelength_sampling: str, progress: bool = False,
                      task_passes: int | None = None) -> ClusterRun:
    """Render passes ``first_pass`` .. ``first_pass + spp - 1`` of ``scene`` on ``client``'s cluster (see the
    module docstring); ``mode`` is the render's colour mode (for the film)."""
    from ..checks import integer

    distributed = require_distributed()
    threads = worker_threads(client)
    task_passes = default_task_passes(spp, threads) if task_passes is None else integer(task_passes, "task_passes",
                                                                                         low=1)
    starts = list(range(first_pass, first_pass + spp, task_passes))
    token = uuid.uuid4().hex[:12]
    film = Film(scene.camera.width, scene.camera.height, covariance=mode.film_covariance, to_srgb=mode.film_to_srgb)
    counters, task_seconds, workers = Counters(), 0.0, set()
    bar = progress_bar(progress, spp, "spp", f"rendering on the cluster ({estimator.name})")
    clock = time.perf_counter()
    shipments = Shipments(client, ScenePayload.of(scene))
    index_of: dict = {}   # task key -> (task index, times submitted before, the futures it was given)
    waiting: dict[int, tuple] = {}   # finished tasks waiting for the tasks before them (their films stay on workers)
    merged = submitted = peak = 0
    counted = time.perf_counter()
    done = distributed.as_completed(loop=client.loop)

    def submit_task(index: int, attempt: int = 0) -> None:
        start = starts[index]
        count = min(task_passes, first_pass + spp - start)
        future, given = shipments.submit(render_passes, estimator, seed, start, count, spectral, wavelength_sampling,
                                         key=f"pathspace-passes-{token}-{index}", attempt=attempt)
        index_of[future.key] = (index, attempt, given)
        done.add(future)

    def submit() -> None:
        nonlocal submitted, threads, counted
        if time.perf_counter() - counted > WORKER_RECOUNT_SECONDS:  # workers that joined since the start count too
            threads, counted = max(threads, sum(client.nthreads().values())), time.perf_counter()
        while submitted < len(starts) and submitted - merged < 2 * threads:
            submit_task(submitted)
            submitted += 1

    def result_of(index: int):
        """The result of finished task ``index``, or None if the cluster lost it with the scene (the task is
        submitted again)."""
        future, attempt, given = waiting.pop(index)
        try:
            return future.result()
        except Exception as error:
            if future.status == "cancelled" and shipments.lost_by(given):
                submit_task(index, attempt + 1)
                return None
            last = min(starts[index] + task_passes, first_pass + spp) - 1
            error.add_note(f"in the cluster task of passes {starts[index]} .. {last}")
            raise

    try:
        submit()
        for future in done:  # each task's future once, when it has finished (after any retries)
            index, attempt, given = index_of.pop(future.key)
            waiting[index] = (future, attempt, given)
            if future.status != "finished":
                result_of(index)   # raises the task's error, or (lost with the scene) submits it again
                continue
            peak = max(peak, len(waiting))
            while merged in waiting:  # its film is fetched only now: the client holds one task film at a time
                result = result_of(merged)
                if result is None:
                    break
                film.merge(result.film)
                counters.merge(result.counters)
                task_seconds += result.seconds
                workers.add(result.worker)
                merged += 1
                if bar is not None:
                    bar.update(result.film.passes)
                    bar.set_postfix_str(f"{merged}/{len(starts)} tasks")
            submit()
    finally:
        outstanding = list(done.futures)  # not finished: the render stopped early
        if outstanding:
            client.cancel(outstanding)
        shipments.release()
        if bar is not None:
            bar.close()
    seconds = time.perf_counter() - clock
    stats = {"cluster": {"scheduler": client.scheduler.address, "threads": threads, "workers_used": len(workers),
                         "tasks": len(starts), "task_passes": task_passes, "task_seconds": task_seconds,
                         "tasks_waiting_peak": peak, "scene_reships": shipments.renewals}}
    return ClusterRun(film, counters, seconds, threads, stats)
