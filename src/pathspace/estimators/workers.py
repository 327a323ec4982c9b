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

from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterable, Iterator, Sequence, TypeVar

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


def in_parallel(threads: int, work: Callable[[T], R], items: Sequence[T]) -> list[R]:
    """``[work(item) for item in items]``, run on up to ``threads`` threads.

    The first failure (or :class:`~pathspace.estimators.control.Interrupted`)
    is raised once the calls already running have ended; calls not yet
    started are dropped.
    """
    if threads <= 1 or len(items) <= 1:
        return [work(item) for item in items]
    pool = ThreadPoolExecutor(min(threads, len(items)))
    try:
        return list(pool.map(work, items))
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def in_rounds(threads: int, work: Callable[[T], R], items: Iterable[T]) -> Iterator[tuple[T, R]]:
    """``(item, work(item))`` in item order, computed ``threads`` at a time (so that at most that many results,
    e.g. a bootstrap batch's chain states, are held at once)."""
    pending = list(items)
    for first in range(0, len(pending), max(threads, 1)):
        round_items = pending[first:first + max(threads, 1)]
        yield from zip(round_items, in_parallel(threads, work, round_items))
