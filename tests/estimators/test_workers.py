"""Pieces of a Metropolis render on threads: the split depends on the size alone, results come in order, and a
failure in a piece is raised."""
from __future__ import annotations

import threading

import pytest

from pathspace.estimators.workers import in_parallel, in_rounds, split


@pytest.mark.parametrize("count,size", [(1, 4), (4, 4), (5, 4), (16383, 4096), (16384, 4096), (40000, 16384)])
def test_split_covers_the_lanes_in_near_equal_slices(count, size):
    parts = split(count, size)
    assert parts[0].start == 0 and parts[-1].stop == count
    assert all(a.stop == b.start for a, b in zip(parts, parts[1:]))
    lengths = [p.stop - p.start for p in parts]
    assert max(lengths) <= size and max(lengths) - min(lengths) <= 1
    assert len(parts) == -(-count // size)


def test_results_come_in_item_order_from_several_threads():
    seen = set()

    def work(k: int) -> int:
        seen.add(threading.get_ident())
        return sum(range(k * 20000))      # enough work for the pool to use both threads

    items = list(range(12))
    assert in_parallel(2, work, items) == [work(k) for k in items]
    assert [(k, r) for k, r in in_rounds(3, work, items)] == [(k, work(k)) for k in items]
    assert len(seen) >= 2


def test_a_failure_in_a_piece_is_raised():
    def work(k: int) -> int:
        if k == 3:
            raise RuntimeError("piece 3 failed")
        return k

    with pytest.raises(RuntimeError, match="piece 3 failed"):
        in_parallel(2, work, list(range(6)))
    with pytest.raises(RuntimeError, match="piece 3 failed"):
        list(in_rounds(2, work, range(6)))
