"""The default render loop: passes x tiles, on worker threads, results to the film in item order.

A render of ``spp`` samples per pixel is ``spp`` passes over the image.  Work
items hold at most about ``tile_pixels`` lanes: a tile of a large image, or
several passes of a small one (:func:`work_layout`); each (pass, tile) unit
has its own random streams (see :mod:`pathspace.sampler`).  One worker thread
per core runs the estimator's ``render_items`` on its own wavefront, taking
items as it needs them -- NumPy and Embree release the GIL in their inner
loops -- and the main thread hands results to the film in item order, so the
same seed gives the bit-identical image whatever the thread count.  Items
never straddle a checkpoint given in passes, and a checkpoint in seconds
falls between two items, so every checkpoint sees whole passes.  A render
that saves its state (``job.autosave``, see :mod:`pathspace.resume`) saves at
such moments too -- whole passes, with the clock paused -- once its interval
has passed.
"""
from __future__ import annotations

import threading
from typing import Callable, Iterator

from .base import Budget, Checkpoint, Counters, ItemResult, RenderJob, WorkItem
from .control import Interrupted

__all__ = ["render_passes", "work_layout"]

# With a time budget, items hold at most 1 / TIMED_ITEM_SHARE of the lanes they would otherwise, and a
# small image's passes are grouped into items that take a worker about TIMED_ITEM_SECONDS of the budget.
TIMED_ITEM_SHARE = 4
TIMED_ITEM_SECONDS = 0.1
TIMED_FIRST_LANES = 4096  # the first items' lanes: fewer would spend their time in per-bounce overhead


def work_layout(pixel_count: int, passes: int | None, workers: int, tile_pixels: int) -> tuple[int, int]:
    """(tile size in pixels, passes per work item) for an image of ``pixel_count`` pixels, in items of
    about ``tile_pixels`` lanes.

    Small images pack several passes into an item, but no more than keeps
    every worker busy when the number of ``passes`` is known.  With a time
    budget (``passes`` None) items hold a quarter as many lanes -- work in
    flight at the deadline is dropped, and an item's last steps (connections,
    splats) run between clock checks, so it is cut finer.  The grouping
    changes neither the random streams nor the order in which samples reach
    the film.
    """
    if passes is None:
        tile_pixels = max(1, tile_pixels // TIMED_ITEM_SHARE)
    tiles = -(-pixel_count // tile_pixels)
    tile = -(-pixel_count // tiles)
    if tiles > 1:
        return tile, 1
    if passes is None:
        return tile, max(1, tile_pixels // pixel_count)
    return tile, min(max(1, tile_pixels // pixel_count), max(1, -(-passes // (2 * workers))))


def _pass_groups(passes: Iterator[int], size: Callable[[], int], first: int, breaks: set[int]) -> Iterator[range]:
    """Consecutive passes in groups of at most ``size()``; a group also ends after pass ``first + b - 1``
    for every b in ``breaks`` (so that checkpoints fall between groups)."""
    group: list[int] = []
    for p in passes:
        group.append(p)
        if len(group) >= size() or p - first + 1 in breaks:
            yield range(group[0], group[-1] + 1)
            group = []
    if group:
        yield range(group[0], group[-1] + 1)


class _TimedItemSize:
    """Passes per item under a time budget, from the items' own durations: starting from ``first``
    passes (at most ``largest``), the size doubles while a worker's last item took under half of
    TIMED_ITEM_SECONDS of the budget and halves while it took over twice that (a pass's cost is known
    only once passes have run)."""

    def __init__(self, seconds: float, first: int, largest: int) -> None:
        self.target, self.largest, self.size = TIMED_ITEM_SECONDS * seconds, largest, min(first, largest)

    def __call__(self) -> int:
        return self.size

    def observe(self, seconds: float, passes: int) -> None:
        """A worker finished an item of ``passes`` passes in ``seconds``."""
        if seconds < 0.5 * self.target and passes >= self.size:
            self.size = min(self.largest, 2 * self.size)
        elif seconds > 2.0 * self.target:
            self.size = max(1, self.size // 2)


def _work_items(job: RenderJob, budget: Budget, tile: int, size: Callable[[], int]) -> Iterator[WorkItem]:
    """Work items in order: passes until the budget is spent, each group of ``size()`` passes tile by tile."""
    control, pixel_count = job.control, job.film.pixel_count

    def passes() -> Iterator[int]:
        p = 0
        while ((budget.spp is not None and p < budget.spp)
               or (budget.seconds is not None and (p == 0 or control.elapsed() < budget.seconds))):
            yield budget.first_pass + p
            p += 1

    breaks = {int(c) for c in budget.checkpoints} if budget.checkpoint_unit == "spp" else set()
    index = 0
    for group in _pass_groups(passes(), size, budget.first_pass, breaks):
        for start in range(0, pixel_count, tile):
            yield WorkItem(index, group, start // tile, start, min(start + tile, pixel_count))
            index += 1


class _Checkpoints:
    """Fires ``on_checkpoint`` once the film has reached each checkpoint, and saves the render's state
    when ``job.autosave`` says it is due, with the clock paused and whole passes on the film."""

    def __init__(self, budget: Budget, job: RenderJob, on_checkpoint: Callable[[Checkpoint], None] | None) -> None:
        self.pending = sorted(budget.checkpoints) if on_checkpoint is not None else []
        self.unit, self.job, self.callback = budget.checkpoint_unit, job, on_checkpoint
        self.start = job.film.passes  # a resumed render's film starts with the passes of earlier sessions

    def update(self) -> None:
        film, control, autosave = self.job.film, self.job.control, self.job.autosave
        if film.incomplete_passes or not film.passes:
            return
        reached = film.passes - self.start if self.unit == "spp" else control.elapsed()
        checkpoint = bool(self.pending) and self.pending[0] <= reached
        save = autosave is not None and autosave.due()
        if not checkpoint and not save:
            return
        while self.pending and self.pending[0] <= reached:
            self.pending.pop(0)
        control.pause()
        try:
            state = Checkpoint(film.passes, control.elapsed(), film)
            if checkpoint:
                self.callback(state)
            if save:
                autosave.save(state)
        finally:
            control.resume()


def render_passes(estimator, job: RenderJob, budget: Budget,
                  on_checkpoint: Callable[[Checkpoint], None] | None = None) -> None:
    """Render ``budget`` with ``estimator.render_items`` on ``job.threads`` workers into ``job.film``."""
    film, control = job.film, job.control
    tile, per_item = work_layout(film.pixel_count, budget.spp, job.threads, estimator.tile_pixels)
    timed = None
    if budget.seconds is not None:
        timed = _TimedItemSize(budget.seconds, -(-TIMED_FIRST_LANES // tile), per_item)
    items = _work_items(job, budget, tile, timed or (lambda: per_item))
    lock, done = threading.Lock(), threading.Condition()
    results: dict[int, ItemResult] = {}
    failures: list[BaseException] = []
    counters = [Counters() for _ in range(job.threads)]
    running = [job.threads]
    handed: dict[int, tuple[float, int]] = {}  # thread -> (clock, passes) of the item it took last

    def next_item() -> WorkItem | None:
        control.check()
        with lock:
            now, thread = control.elapsed(), threading.get_ident()
            if timed is not None and thread in handed:
                timed.observe(now - handed[thread][0], handed[thread][1])
            item = next(items, None)
            if item is not None:
                handed[thread] = (now, len(item.passes))
            return item

    def work(k: int) -> None:
        try:
            for result in estimator.render_items(job, next_item, counters[k]):
                with done:
                    results[result.item.index] = result
                    done.notify()
        except Interrupted:
            pass
        except BaseException as error:  # handed to the main thread
            failures.append(error)
            control.cancel(f"a worker failed: {error!r}")
        finally:
            with done:
                running[0] -= 1
                done.notify()

    control.deadline = budget.seconds
    workers = [threading.Thread(target=work, args=(k,), daemon=True) for k in range(job.threads)]
    for w in workers:
        w.start()
    checkpoints = _Checkpoints(budget, job, on_checkpoint)
    expected = 0
    try:
        while True:
            with done:
                while expected not in results and running[0] and not failures:
                    done.wait()
                if failures or expected not in results:
                    break
                result = results.pop(expected)
            expected += 1
            before = film.passes
            result.deliver(film)
            if job.progress is not None and film.passes > before:
                job.progress.update(film.passes - before)
            checkpoints.update()
    except BaseException:
        control.cancel("interrupted")
        raise
    finally:
        for w in workers:
            w.join()
        for c in counters:
            job.counters.merge(c)
    if failures:
        raise failures[0]
    film.discard_incomplete()
