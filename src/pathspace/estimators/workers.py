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

from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from typing import Callable, Iterable, Iterator, Sequence, TypeVar

from .control import Interrupted, RenderControl

__all__ = ["PIECE", "in_parallel", "in_rounds", "split"]

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
    if threads <= 1 or len(items) <= 1:
        return [work(item) for item in items]
    pool = ThreadPoolExecutor(min(threads, len(items)))
    try:
        futures = [pool.submit(work, item) for item in items]
        wait(futures, return_when=FIRST_EXCEPTION)
        failures = [f.exception() for f in futures if f.done() and f.exception() is not None]
        errors = [e for e in failures if not isinstance(e, Interrupted)]
        if errors and control is not None:
            control.cancel(f"a worker failed: {errors[0]!r}")
        wait(futures)
    except BaseException:
        if control is not None:
            control.cancel("interrupted")
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    failures = [f.exception() for f in futures if f.exception() is not None]
    if failures:
        raise next((e for e in failures if not isinstance(e, Interrupted)), failures[0])
    return [f.result() for f in futures]


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
