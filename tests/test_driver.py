"""The render driver and the estimator contract: progressive checkpoints, thread- and grouping-independent
images, estimators that own their loop, failures inside workers, and the clock."""
from __future__ import annotations

import dataclasses
import time
from typing import ClassVar

import numpy as np
import pytest

import pathspace as ps
from pathspace.estimators import ESTIMATORS
from pathspace.estimators.base import Estimator, ItemResult, WorkItem
from pathspace.estimators.passes import TIMED_FIRST_LANES
from conftest import scene_dict


@pytest.fixture(scope="module")
def small():
    return ps.scene_from_dict(scene_dict("cornell-box-thin-lens", (12, 10)))


@pytest.mark.parametrize("estimator", ["pt", "lt", "bdpt"])
def test_a_checkpoint_equals_a_render_of_its_passes(small, estimator):
    """Developing the film at 1, 3 and 8 passes of a 12-pass render gives, bit for bit, the renders of
    1, 3 and 8 passes: one run serves every budget."""
    seen = {}

    def look(checkpoint):
        seen[checkpoint.passes] = (checkpoint.film.mean().copy(), checkpoint.film.variance().copy())

    final = ps.render(small, estimator, spp=12, seed=4, checkpoints=[1, 3, 8], on_checkpoint=look)
    assert sorted(seen) == [1, 3, 8]
    for passes, (mean, variance) in seen.items():
        alone = ps.render(small, estimator, spp=passes, seed=4)
        np.testing.assert_array_equal(mean, alone.film.mean())
        np.testing.assert_array_equal(variance[np.isfinite(variance)], alone.film.variance()[np.isfinite(variance)])
    np.testing.assert_array_equal(final.image, ps.render(small, estimator, spp=12, seed=4).image)


@pytest.mark.parametrize("estimator", ["pt", "lt", "bdpt"])
def test_images_do_not_depend_on_threads(small, estimator):
    """Items group several passes of a small image; how many depends on the thread count, the image not."""
    one = ps.render(small, estimator, spp=9, seed=2, threads=1, pyramid=2) if estimator != "pt" else \
        ps.render(small, estimator, spp=9, seed=2, threads=1)
    params = {"pyramid": 2} if estimator != "pt" else {}
    two = ps.render(small, estimator, spp=9, seed=2, threads=2, **params)
    np.testing.assert_array_equal(one.image, two.image)
    if estimator != "pt":
        for key in one.strategies:
            np.testing.assert_array_equal(one.strategies[key]["weighted"], two.strategies[key]["weighted"])


def test_time_checkpoints_see_whole_passes(small):
    seen = []
    result = ps.render(small, "pt", time=1.5, seed=1, checkpoints=[0.1, 0.3],
                       on_checkpoint=lambda c: seen.append((c.passes, c.seconds, c.film.mean().copy())))
    assert [s for _, s, _ in seen] == sorted(s for _, s, _ in seen) and len(seen) >= 1
    for passes, seconds, mean in seen:
        assert seconds >= 0.1 and 1 <= passes <= result.stats["spp"]
        np.testing.assert_array_equal(mean, ps.render(small, "pt", spp=passes, seed=1).film.mean())


def test_checkpoint_time_is_not_render_time(small):
    """The clock stops while the film is looked at (and workers wait)."""
    start = time.perf_counter()
    result = ps.render(small, "pt", spp=40, seed=1, checkpoints=[10, 20, 30], on_checkpoint=lambda c: time.sleep(0.3))
    wall = time.perf_counter() - start
    assert result.stats["seconds"] < wall - 0.85


def test_disjoint_pass_ranges_merge_to_the_whole(small):
    whole = ps.render(small, "bdpt", spp=6, seed=3)
    first = ps.render(small, "bdpt", spp=2, seed=3)
    second = ps.render(small, "bdpt", spp=4, seed=3, first_pass=2)
    first.film.merge(second.film)
    np.testing.assert_allclose(first.film.mean(), whole.film.mean(), rtol=1e-12)
    assert first.film.passes == 6


@dataclasses.dataclass
class Broken(Estimator):
    """Fails in its second work item."""

    name = "broken"

    def plan(self, scene):
        return ["fails"]

    def render_items(self, job, next_item, counters):
        while (item := next_item()) is not None:
            if item.index == 1:
                raise RuntimeError("deliberate failure in a worker")
            yield ItemResult(item, np.zeros((3, item.pixels.size)))


def test_a_failing_worker_stops_the_render(small):
    with pytest.raises(RuntimeError, match="deliberate failure in a worker"):
        ps.render(small, Broken(), spp=200, threads=2)


@dataclasses.dataclass
class Constant(Estimator):
    """An estimator without passes: it owns its loop and writes every pixel's value as one splat per
    'sample' -- the shape a Markov-chain estimator takes."""

    value: float = 0.25
    name = "constant"

    def plan(self, scene):
        return ["every pixel is the constant"]

    def render(self, job, budget, on_checkpoint=None):
        film = job.film
        pixels = np.arange(film.pixel_count)
        for k in range(budget.spp):
            job.control.check()
            film.add_splats(k, pixels, np.full((3, pixels.size), self.value))
            film.add_samples(k, 0, np.zeros((3, pixels.size)))
            if on_checkpoint is not None and k + 1 in budget.checkpoints:
                on_checkpoint(ps.estimators.base.Checkpoint(k + 1, job.control.elapsed(), film))


def test_an_estimator_may_own_its_loop(small, monkeypatch):
    """Registered in one line, rendered by name, checkpointed like any other."""
    monkeypatch.setitem(ESTIMATORS, "constant", Constant)
    seen = []
    result = ps.render(small, "constant", spp=5, value=0.5, checkpoints=[2], on_checkpoint=lambda c: seen.append(c.passes))
    np.testing.assert_array_equal(result.image, 0.5)
    assert np.all(result.variance == 0) and seen == [2] and result.stats["spp"] == 5


def test_render_arguments_are_checked(small):
    for kwargs, message in (({"spp": 0}, "spp: expected an integer >= 1"), ({"time": -1}, "time: expected"),
                            ({"seed": -2}, "seed: expected an integer >= 0"), ({"threads": 0}, "threads"),
                            ({"spp": 4, "time": 1.0}, "either spp or time"),
                            ({"checkpoints": [0]}, "checkpoints: expected")):
        with pytest.raises(ValueError, match=message):
            ps.render(small, "pt", **kwargs)


def test_a_worker_takes_no_item_it_could_not_finish_by_the_deadline():
    from pathspace.estimators.passes import _Deadline

    deadline = _Deadline(10.0)
    assert deadline.admits("a", 9.9)           # nothing to go by
    deadline.handed("a", 0, 0.0)
    deadline.handed("b", 1, 0.0)
    assert deadline.admits("a", 5.0) and not deadline.admits("a", 5.1)  # the age of its oldest item, 5.1 s
    deadline.finished(0, 3.0)                  # a's item took 3 s
    deadline.handed("a", 2, 3.0)
    assert deadline.admits("a", 7.0) and not deadline.admits("a", 7.5)  # its last latency, not its items' ages
    assert not deadline.admits("b", 6.0)       # b's item, handed out at 0, is still running
    deadline.finished(1, 1.0)
    assert deadline.admits("b", 6.0) and deadline.admits("b", 9.0) and not deadline.admits("b", 9.5)


@dataclasses.dataclass
class Steady(Estimator):
    """Every item takes 0.15 s of wall time (asleep, as a worker waiting for Embree would be); the items
    handed out are listed in ``handed``."""

    name = "steady"
    handed: ClassVar[list[int]] = []

    def plan(self, scene):
        return ["sleeps"]

    def render_items(self, job, next_item, counters):
        while (item := next_item()) is not None:
            self.handed.append(item.index)
            time.sleep(0.15)
            job.control.check()   # past the deadline: the item is dropped
            yield ItemResult(item, np.zeros((3, item.pixels.size)))


def test_timed_workers_deliver_every_item_they_take(small):
    """Under a time budget a worker stops taking items once the next would end after the deadline, so
    that no work is thrown away (items taken until the deadline were dropped in flight: 7-10% of an 8-s
    render, most of a 0.3-s one)."""
    Steady.handed.clear()
    result = ps.render(small, Steady(), time=1.0, threads=1)
    per_item = TIMED_FIRST_LANES // small.camera.pixel_count   # passes of the whole image per item
    assert len(Steady.handed) >= 4 and result.stats["spp"] == per_item * len(Steady.handed)
    assert 0.5 <= result.stats["seconds"] <= 1.0


def test_a_drained_wavefront_asks_once_more(small):
    """A path tracer refused an item (as a time budget's deadline refuses one that would end too late, queued
    behind the wavefront's paths) lets its wavefront drain and asks once more, since an item alone ends sooner;
    refused again, it stops.  (Time-budgeted pt renders ended 0.6-1.9 s before an 8-s deadline.)"""
    pt = ESTIMATORS["pt"](max_depth=3)
    answers = []

    def render_items(job, next_item, counters):
        def refusing_once():
            item = None if len(answers) == 1 else next_item()
            answers.append(item is not None)
            return item

        yield from type(pt).render_items(pt, job, refusing_once, counters)

    pt.render_items = render_items
    result = ps.render(small, pt, spp=8, threads=1)   # two items of four passes
    assert answers == [True, False, True, False, False] and result.stats["spp"] == 8


def test_timed_items_grow_while_short_and_shrink_when_long():
    from pathspace.estimators.passes import TIMED_ITEM_SECONDS, _TimedItemSize

    # A 64x64 image (4096 pixels): 1024 lanes are a quarter of it, 8192 two passes of all of it.
    size = _TimedItemSize(10.0, 4096, first=1024, largest=8192)  # target: TIMED_ITEM_SECONDS x 10 s per item
    target = TIMED_ITEM_SECONDS * 10.0
    assert size.layout() == (1024, 1)
    for expected in ((2048, 1), (4096, 1), (4096, 2), (4096, 2)):
        tile, passes = size.layout()
        size.observe(0.1 * target, tile * passes)
        assert size.layout() == expected
    size.observe(0.1 * target, 1000)  # a short item smaller than the current size says nothing
    assert size.layout() == (4096, 2)
    size.observe(3.0 * target, 8192)
    assert size.layout() == (4096, 1)
    size.observe(1.0 * target, 4096)  # on target: unchanged
    assert size.layout() == (4096, 1)
    assert _TimedItemSize(1.0, 4096, first=50_000, largest=8192).layout() == (4096, 2)
    assert _TimedItemSize(1.0, 10_000, first=4096, largest=8192).layout() == (3334, 1)  # equal tiles


def test_pass_of_gives_every_lane_its_pass():
    """A work item's lanes run unit after unit (a pass of its tile each): lane k is in pass passes[k // tile]."""
    item = WorkItem(0, range(5, 8), tile=2, pixel_start=10, pixel_stop=14)
    lanes = np.array([0, 3, 4, 7, 8, 11])
    assert item.pass_of(lanes).tolist() == [5, 5, 6, 6, 7, 7]
    assert item.pass_of(np.arange(12)).tolist() == np.repeat([5, 6, 7], 4).tolist()
    single = WorkItem(1, range(9, 10), tile=0, pixel_start=0, pixel_stop=4)
    assert single.pass_of(np.array([0, 3])) == 9   # one pass: an int, not a gather per splat
