"""Independent pieces of one render on the render's threads, with results in a fixed order.

The Metropolis estimators run as one process of chains rather than as
passes of work items (:mod:`pathspace.estimators.passes`), so they split
their work themselves: the chains into groups that step independently, the
bootstrap into batches, a pass of direct paths into pixel ranges.  Each
piece has its own random stream, and how the work is split depends on its
size alone (:func:`split`), never on the thread count: the image is bit for
bit the same on any number of threads.  NumPy and Embree release the GIL in
their inner loops, so the pieces run in parallel.
"""
from __future__ import annotations

from collections import deque
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from typing import Callable, Iterable, Iterator, Sequence, TypeVar

from .control import Interrupted, RenderControl

__all__ = ["PIECE", "in_order", "in_parallel", "in_rounds", "split"]

T = TypeVar("T")
R = TypeVar("R")

# Lanes per piece.  A chain step or a bootstrap batch is a wavefront that ends with its longest path, and each of
# its bounces costs about 2 ms of Python and NumPy call overhead whatever its width (PSSMLT over PT, 128 x 128 Cornell
# box, max_depth 16): pieces of 4096 chains made one thread 1.5x slower than one piece of 16384, and the overhead
# holds the GIL, so two threads then ran no faster than one.  Pieces of 16384 chains: 1.28x on two threads.
PIECE = 16384


def split(count: int, size: int = PIECE) -> list[slice]:
    """``count`` lanes (chains, pixels) in contiguous slices of at most ``size``, as equal as can be."""
    parts = max(1, -(-count // size))
    edges = [count * k // parts for k in range(parts + 1)]
    return [slice(a, b) for a, b in zip(edges, edges[1:])]


def in_parallel(threads: int, work: Callable[[T], R], items: Sequence[T],
                control: RenderControl | None = None) -> list[R]:
    """``[work(item) for item in items]``, run on up to ``threads`` threads.

    When a call fails, or the caller is interrupted while it waits (Ctrl-C),
    ``control`` is cancelled so that the other calls stop at their next
    check; once every call has ended, the first failure other than
    :class:`~pathspace.estimators.control.Interrupted` is raised (a render
    stopped by its deadline or a signal raises Interrupted).
    """
    return [result for _, result in in_order(threads, work, items, control, ahead=len(items))]


def in_rounds(threads: int, work: Callable[[T], R], items: Iterable[T],
              control: RenderControl | None = None) -> Iterator[tuple[T, R]]:
    """``(item, work(item))`` in item order, computed in rounds of ``threads`` consecutive items by
    :func:`in_parallel`.  A round starts only when the caller asks for its first result, so the caller has
    consumed every result of the round before: at most ``threads`` results are held at once, and the items of a
    round may share what the items of other rounds use (a bootstrap's reusable chain states)."""
    pending = list(items)
    size = max(threads, 1)
    for first in range(0, len(pending), size):
        round_items = pending[first:first + size]
        yield from zip(round_items, in_parallel(threads, work, round_items, control))


def in_order(threads: int, work: Callable[[T], R], items: Iterable[T], control: RenderControl | None = None,
             ahead: int | None = None) -> Iterator[tuple[T, R]]:
    """``(item, work(item))`` in item order, computed on up to ``threads`` threads as they come free.

    Unlike :func:`in_rounds`, a long item does not hold the others back: an item starts as soon as a thread is
    free and fewer than ``ahead`` items (default: twice the threads; at least the threads) are running or done
    but not yet consumed, so at most ``ahead`` results are held at once.  Items must not share state.  Failures
    are handled as in :func:`in_parallel`, as soon as a call fails rather than when its turn comes, and items
    not started by then never start.  On more than one thread, a caller that stops while items remain (Ctrl-C,
    or closing the iterator) cancels ``control`` too, so that the threads stop at their next check; on one
    thread the items run in the caller's thread, one per result asked for.
    """
    pending = list(items)
    if threads <= 1 or len(pending) <= 1:
        for item in pending:
            yield item, work(item)
        return
    ahead = max(ahead if ahead is not None else 2 * threads, threads)
    pool = ThreadPoolExecutor(min(threads, len(pending)))
    running: deque[tuple[T, Future]] = deque()
    submitted, failure = 0, None
    try:
        while failure is None and (running or submitted < len(pending)):
            while submitted < len(pending) and len(running) < ahead:
                running.append((pending[submitted], pool.submit(work, pending[submitted])))
                submitted += 1
            futures = [future for _, future in running]
            while not futures[0].done() and not _failed(futures):
                wait([future for future in futures if not future.done()], return_when=FIRST_COMPLETED)
            if _failed(futures):
                failure = _first_failure(futures, control)
            else:
                item, future = running.popleft()
                yield item, future.result()
    except BaseException:
        if control is not None and (running or submitted < len(pending)):
            control.cancel("interrupted")
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    if failure is not None:
        raise failure


def _failed(futures: list[Future]) -> bool:
    """Whether one of ``futures`` has ended with an exception."""
    return any(f.done() and f.exception() is not None for f in futures)


def _first_failure(futures: list[Future], control: RenderControl | None) -> BaseException:
    """Some of ``futures`` failed: the ones not started never start; ``control`` is cancelled as soon as one has
    failed other than by an interruption (before and after waiting for the running ones); returns the first
    failure other than an interruption (else the first interruption)."""
    for future in futures:
        future.cancel()

    def failures() -> list[BaseException]:
        found = [f.exception() for f in futures if f.done() and not f.cancelled() and f.exception() is not None]
        errors = [e for e in found if not isinstance(e, Interrupted)]
        if errors and control is not None and not control.cancelled:
            control.cancel(f"a worker failed: {errors[0]!r}")
        return errors + [e for e in found if isinstance(e, Interrupted)]

    failures()
    wait(futures)
    return failures()[0]
