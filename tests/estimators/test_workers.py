"""Pieces of a Metropolis render on threads: the split depends on the size alone, results come in order, a
failure in a piece stops the others and is raised, and rounds let pieces share what other rounds use."""
from __future__ import annotations

import threading
import time

import pytest

from pathspace.estimators.control import Interrupted, RenderControl
from pathspace.estimators.workers import in_parallel, in_rounds, split


@pytest.mark.parametrize("count,size", [(1, 4), (4, 4), (5, 4), (16383, 4096), (16384, 4096), (40000, 16384)])
def test_split_covers_the_lanes_in_near_equal_slices(count, size):
    parts = split(count, size)
    assert parts[0].start == 0 and parts[-1].stop == count
    assert all(a.stop == b.start for a, b in zip(parts, parts[1:]))
    lengths = [p.stop - p.start for p in parts]
    assert max(lengths) <= size and max(lengths) - min(lengths) <= 1
    assert len(parts) == -(-count // size)


def test_results_come_in_item_order_from_two_threads():
    both = threading.Barrier(2, timeout=30)   # the first two items wait for each other: two threads run them

    def work(k: int) -> int:
        if k < 2:
            both.wait()
        return k * k

    items = list(range(12))
    assert in_parallel(2, work, items) == [k * k for k in items]
    both.reset()
    assert list(in_rounds(2, work, items)) == [(k, k * k) for k in items]


def test_a_failure_cancels_the_other_pieces_and_wins_over_their_interruptions():
    control = RenderControl()
    failed = threading.Event()

    def work(k: int) -> int:
        if k == 1:
            failed.set()
            raise RuntimeError("piece 1 failed")
        failed.wait(30)
        for _ in range(30000):   # runs until the failure cancels the render (at most about 30 s)
            control.check()
            time.sleep(0.001)
        return k

    with pytest.raises(RuntimeError, match="piece 1 failed"):
        in_parallel(2, work, [0, 1], control)
    assert control.cancelled and "piece 1 failed" in control.reason


def test_an_interruption_alone_is_raised_as_such():
    def work(k: int) -> int:
        if k == 3:
            raise Interrupted("the time budget is spent")
        return k

    control = RenderControl()
    with pytest.raises(Interrupted):
        in_parallel(2, work, list(range(6)), control)
    assert not control.cancelled    # a deadline is not a failure: the render keeps what it completed


def test_a_round_starts_after_the_previous_one_is_consumed():
    started, consumed = [], []

    def work(k: int) -> int:
        started.append((k, len(consumed)))
        return k

    for k, _ in in_rounds(2, work, range(6)):
        consumed.append(k)
    assert all(seen >= 2 * (k // 2) for k, seen in started)   # items 2 and 3 start after 0 and 1 are consumed
