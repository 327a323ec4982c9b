"""Pieces of a Metropolis render on threads: the split depends on the size alone, results come in order, a
failure in a piece stops the others and is raised, rounds let pieces share what other rounds use, and in_order
lets short pieces run beside a long one with a bounded number of results held."""
from __future__ import annotations

import threading
import time

import pytest

from pathspace.estimators.control import Interrupted, RenderControl
from pathspace.estimators.workers import in_order, in_parallel, in_rounds, split


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


def test_in_order_runs_short_items_beside_a_long_first_one():
    """Item 0 waits until items 1-3 are done: with rounds of two it would wait forever (here: 30 s and fail);
    in_order runs them on the other thread, and still yields in item order."""
    three_done = threading.Barrier(2, timeout=30)

    def work(k: int) -> int:
        if k == 0 or k == 3:
            three_done.wait()   # item 0 passes once item 3 has run: items 1-3 ran on the second thread
        return k * k

    assert list(in_order(2, work, range(8))) == [(k, k * k) for k in range(8)]


@pytest.mark.parametrize("ahead", [2, 3, 5])
def test_in_order_holds_at_most_ahead_results(ahead):
    started, consumed = [], []
    lock = threading.Lock()

    def work(k: int) -> int:
        with lock:
            started.append((k, len(consumed)))
        return k

    for k, _ in in_order(2, work, range(12), ahead=ahead):
        with lock:
            consumed.append(k)
    assert sorted(k for k, _ in started) == list(range(12))
    assert all(k < seen + ahead for k, seen in started)   # item k starts once items before k - ahead are consumed


def test_in_order_raises_a_failure_before_the_long_item_ahead_of_it_ends():
    control = RenderControl()

    def work(k: int) -> int:
        if k == 1:
            raise RuntimeError("piece 1 failed")
        for _ in range(30000):   # item 0 runs until the failure cancels the render (at most about 30 s)
            control.check()
            time.sleep(0.001)
        return k

    began = time.perf_counter()
    with pytest.raises(RuntimeError, match="piece 1 failed"):
        list(in_order(2, work, range(4), control))
    assert control.cancelled and time.perf_counter() - began < 20


def test_a_caller_that_stops_early_cancels_the_render():
    control = RenderControl()
    results = in_order(2, lambda k: k, range(6), control)
    assert next(results) == (0, 0)
    results.close()
    assert control.cancelled
    control = RenderControl()
    results = in_order(2, lambda k: k, range(6), control)
    assert [k for k, _ in zip(range(6), results)] == list(range(6))
    results.close()                  # closed after its last result: nothing was left to stop
    assert not control.cancelled


def test_items_not_started_when_one_fails_never_start():
    started = []

    def work(k: int) -> int:
        started.append(k)
        if k == 0:
            raise RuntimeError("piece 0 failed")
        time.sleep(0.2)
        return k

    with pytest.raises(RuntimeError, match="piece 0 failed"):
        in_parallel(2, work, list(range(8)))
    assert len(started) <= 3, started    # item 0, the one running beside it, at most one more before the cancel
