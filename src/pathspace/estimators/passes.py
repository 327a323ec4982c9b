"""The default render loop: passes x tiles, on worker threads, results to the film in item order.

A render of ``spp`` samples per pixel is ``spp`` passes over the image.  Work
items hold at most about ``tile_pixels`` lanes: a tile of a large image, or
several passes of a small one (:func:`work_layout`); under a time budget the
items start small and follow their own durations (:class:`_TimedItemSize`), and a worker
takes no item it could not finish by the deadline (:class:`_Deadline`): work in flight then
is dropped, and workers that took items to the last moment threw away 7-10% of an 8-s render.
(A path tracer's persistent wavefront, refused, drains and asks once more: alone, an item ends
sooner than queued behind others.)
Each (pass, tile) unit has its own random streams (see :mod:`pathspace.sampler`).
One worker thread per core runs the estimator's ``render_items`` on its own wavefront, taking
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

# With a time budget, items start at TIMED_FIRST_LANES lanes (fewer would spend their time in per-bounce
# overhead) and grow or shrink so that one takes a worker about TIMED_ITEM_SECONDS of the budget.
TIMED_ITEM_SECONDS = 0.1
TIMED_FIRST_LANES = 4096


def _layout(pixel_count: int, lanes: int) -> tuple[int, int]:
    """(tile size in pixels, passes per item) of items of about ``lanes`` lanes: tiles of equal size if the
    image has more pixels than that, else the whole image, as many passes as fit."""
    tiles = -(-pixel_count // lanes)
    tile = -(-pixel_count // tiles)
    return (tile, 1) if tiles > 1 else (tile, max(1, lanes // pixel_count))


def work_layout(pixel_count: int, passes: int, workers: int, tile_pixels: int) -> tuple[int, int]:
    """(tile size in pixels, passes per work item) of a render of ``passes`` passes over an image of
    ``pixel_count`` pixels, in items of about ``tile_pixels`` lanes.

    Small images pack several passes into an item, but no more than keeps
    every worker busy.  The grouping changes neither the random streams nor
    the order in which samples reach the film.
    """
    tile, per_item = _layout(pixel_count, tile_pixels)
    return tile, min(per_item, max(1, -(-passes // (2 * workers))))


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
    """Item layout under a time budget, from the items' own durations: starting from ``first`` lanes (at
    most ``largest``), the lanes per item double while a worker's last item took under half of
    TIMED_ITEM_SECONDS of the budget and halve while it took over twice that (a pass's cost is known
    only once passes have run).  Work in flight at the deadline is dropped, so items stay a small part of
    the budget; long budgets reach the lanes of a render in passes, and its throughput."""

    def __init__(self, seconds: float, pixel_count: int, first: int, largest: int) -> None:
        self.target, self.pixel_count, self.largest = TIMED_ITEM_SECONDS * seconds, pixel_count, largest
        self.lanes = min(first, largest)

    def layout(self) -> tuple[int, int]:
        """(tile size in pixels, passes per item) of the next items."""
        return _layout(self.pixel_count, self.lanes)

    def observe(self, seconds: float, lanes: int) -> None:
        """A worker finished an item of ``lanes`` lanes in ``seconds``."""
        tile, per_item = self.layout()
        if seconds < 0.5 * self.target and lanes >= tile * per_item:
            self.lanes = min(self.largest, 2 * self.lanes)
        elif seconds > 2.0 * self.target:
            self.lanes = max(1, self.lanes // 2)


class _Deadline:
    """Which items a worker may still take under a time budget of ``seconds``: none whose result it
    could not deliver by then.  An item's latency, from being handed out to its result, is predicted
    as that of the worker's last finished item, or before any has finished, as the age of its oldest
    unfinished one (a persistent wavefront holds several items at once, and an item ends with its
    longest path).  Either is at most the clock, so no worker stops taking items before half the
    budget; a worker with nothing to go by takes the item."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self.taken: dict[int, tuple[object, float]] = {}   # item index -> (worker, clock when handed out)
        self.latency: dict[object, float] = {}             # worker -> latency of its last finished item

    def admits(self, worker: object, now: float) -> bool:
        """Whether ``worker`` may take another item at render clock ``now``."""
        if worker in self.latency:
            predicted = self.latency[worker]
        else:
            predicted = max([now - clock for owner, clock in self.taken.values() if owner == worker], default=0.0)
        return now + predicted <= self.seconds

    def handed(self, worker: object, index: int, now: float) -> None:
        """Item ``index`` went to ``worker`` at ``now``."""
        self.taken[index] = (worker, now)

    def finished(self, index: int, now: float) -> None:
        """Item ``index``'s result arrived at ``now``."""
        worker, clock = self.taken.pop(index)
        self.latency[worker] = now - clock


def _work_items(job: RenderJob, budget: Budget, layout: Callable[[], tuple[int, int]]) -> Iterator[WorkItem]:
    """Work items in order: passes until the budget is spent, in groups and tiles as ``layout()`` (tile size,
    passes per item) says when the group is formed."""
    control, pixel_count = job.control, job.film.pixel_count

    def passes() -> Iterator[int]:
        p = 0
        while ((budget.spp is not None and p < budget.spp)
               or (budget.seconds is not None and (p == 0 or control.elapsed() < budget.seconds))):
            yield budget.first_pass + p
            p += 1

    breaks = {int(c) for c in budget.checkpoints} if budget.checkpoint_unit == "spp" else set()
    index = 0
    for group in _pass_groups(passes(), lambda: layout()[1], budget.first_pass, breaks):
        tile = layout()[0]
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
    timed = deadline = None
    if budget.seconds is not None:
        timed = _TimedItemSize(budget.seconds, film.pixel_count, TIMED_FIRST_LANES, estimator.tile_pixels)
        deadline = _Deadline(budget.seconds)
        items = _work_items(job, budget, timed.layout)
    else:
        layout = work_layout(film.pixel_count, budget.spp, job.threads, estimator.tile_pixels)
        items = _work_items(job, budget, lambda: layout)
    lock, done = threading.Lock(), threading.Condition()
    results: dict[int, ItemResult] = {}
    failures: list[BaseException] = []
    counters = [Counters() for _ in range(job.threads)]
    running = [job.threads]
    handed: dict[int, tuple[float, int]] = {}  # thread -> (clock, lanes) of the item it took last

    def next_item() -> WorkItem | None:
        control.check()
        with lock:
            now, thread = control.elapsed(), threading.get_ident()
            if timed is not None and thread in handed:
                timed.observe(now - handed[thread][0], handed[thread][1])
            if deadline is not None and not deadline.admits(thread, now):
                return None
            item = next(items, None)
            if item is not None:
                handed[thread] = (now, len(item.passes) * (item.pixel_stop - item.pixel_start))
                if deadline is not None:
                    deadline.handed(thread, item.index, now)
            return item

    def work(k: int) -> None:
        try:
            for result in estimator.render_items(job, next_item, counters[k]):
                if deadline is not None:
                    with lock:
                        deadline.finished(result.item.index, control.elapsed())
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
