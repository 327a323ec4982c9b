"""Random numbers: streams that depend only on their unit, and numbers that can be recorded and replayed.

The estimators never make their own random numbers; a render with numbers
replayed from a recording of another render must give the bit-identical
image -- for every estimator, RGB and spectral -- which proves that every
number an estimator uses goes through its sampler."""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace.sampler import (RecordingSamplers, ReplaySampler, ReplaySamplers, StreamSampler, StreamSamplers,
                               unit_generator)
from conftest import scene_dict


def test_a_stream_samplers_lanes_stay_in_segment_order():
    """Lanes keep the order of their segments through any keep, split and extend, so that the lanes per
    segment are counted by binary search (``StreamSampler._counts``): checked against bincount."""
    rng = np.random.default_rng(2)
    sampler = StreamSampler(1, [(0, k) for k in range(12)], rng.integers(0, 40, 12))
    for step in range(300):
        action = rng.integers(0, 3)
        if action == 0 and sampler.lanes:
            sampler.keep(np.flatnonzero(rng.random(sampler.lanes) < 0.8))
        elif action == 1 and sampler.lanes:
            part = sampler.split(np.flatnonzero(rng.random(sampler.lanes) < 0.3))
            assert np.all(np.diff(part.unit) >= 0)
            np.testing.assert_array_equal(part.counts, np.bincount(part.unit, minlength=len(part.generators)))
        else:
            sampler.extend(StreamSampler(1, [(1 + step, k) for k in range(3)], rng.integers(0, 30, 3)))
        assert np.all(np.diff(sampler.unit) >= 0)
        np.testing.assert_array_equal(sampler.counts, np.bincount(sampler.unit, minlength=len(sampler.generators)))
        assert sampler.draw(1).shape == (1, sampler.lanes)


def test_a_units_numbers_do_not_depend_on_its_company():
    """Lanes of unit (3, 1) draw the same numbers alone, beside other units, and after others leave."""
    alone = StreamSampler(7, [(3, 1)], [5])
    first = alone.draw(2)
    shared = StreamSampler(7, [(0, 0), (3, 1)], [4, 5])
    np.testing.assert_array_equal(shared.draw(2)[:, 4:], first)
    shared.keep(np.arange(4, 9))          # the first unit's lanes end
    later = StreamSampler(7, [(9, 9)], [3])
    shared.extend(later)                  # a new unit joins behind
    np.testing.assert_array_equal(shared.draw(3)[:, :5], alone.draw(3))
    np.testing.assert_array_equal(unit_generator(7, (3, 1)).random((5, 5))[:2], first)


def test_keep_follows_the_lanes():
    sampler = StreamSampler(1, [(0,)], [6])
    sampler.draw(1)
    sampler.keep(np.array([1, 4]))
    reference = unit_generator(1, (0,))
    reference.random((1, 6))
    np.testing.assert_array_equal(sampler.draw(2), reference.random((2, 2)))
    assert sampler.lanes == 2


def test_replay_serves_each_lanes_row_and_refuses_to_invent_numbers():
    numbers = np.arange(12, dtype=float).reshape(3, 4) / 12
    replay = ReplaySampler(numbers)
    np.testing.assert_array_equal(replay.draw(2), numbers[:, :2].T)
    replay.keep(np.array([0, 2]))
    np.testing.assert_array_equal(replay.draw(1), numbers[[0, 2], 2][None, :])
    with pytest.raises(ValueError, match="needs more than the numbers it was given"):
        replay.draw(2)


def test_replay_with_a_generator_extends_rows_and_remembers_them():
    replay = ReplaySampler(np.full((2, 1), 0.5), rest=np.random.default_rng(0))
    u = replay.draw(3)
    assert u[0].tolist() == [0.5, 0.5] and np.all((u >= 0) & (u < 1))
    np.testing.assert_array_equal(replay.numbers[:, :3], u.T)


def test_recording_then_replaying_numbers_by_hand():
    source = RecordingSamplers(StreamSamplers(3))
    sampler = source.open([(0, 0), (1, 0)], [2, 3])
    a = sampler.draw(2)
    sampler.keep(np.array([0, 3, 4]))
    b = sampler.draw(1)
    replayed = ReplaySamplers(source.recording).open([(0, 0), (1, 0)], [2, 3])
    np.testing.assert_array_equal(replayed.draw(2), a)
    replayed.keep(np.array([0, 3, 4]))
    np.testing.assert_array_equal(replayed.draw(1), b)
    assert np.isnan(source.recording.numbers((0, 0))[1, 2])  # lane 1 ended after two numbers


@pytest.mark.parametrize("name, estimator, params", [
    ("cornell-box", "pt", {}),
    ("cornell-box", "pt", {"light_sampling": "mixture", "rr": "fixed", "rr_depth": 2}),
    ("cornell-box-specular", "pt", {}),
    ("cornell-box-thin-lens", "lt", {}),
    ("cornell-box-specular", "bdpt", {}),
    ("cornell-box-thin-lens", "bdpt", {"rr": "throughput", "pyramid": 2}),
], ids=lambda v: str(v))
def test_replayed_numbers_give_the_same_image(name, estimator, params):
    """Every number each estimator uses comes from its sampler: replaying a recording reproduces the
    render bit for bit (several items, each with several passes, on two threads)."""
    scene = ps.scene_from_dict(scene_dict(name, (12, 10)))
    recording = RecordingSamplers(StreamSamplers(5))
    first = ps.render(scene, estimator, spp=6, samplers=recording, threads=2, **params)
    again = ps.render(scene, estimator, spp=6, samplers=ReplaySamplers(recording.recording), threads=2, **params)
    assert first.image.max() > 0
    np.testing.assert_array_equal(again.image, first.image)
    np.testing.assert_array_equal(again.variance, first.variance)
    # ... and the recording was of the seed's own numbers: the image is the plain render's.
    np.testing.assert_array_equal(first.image, ps.render(scene, estimator, spp=6, seed=5, **params).image)


def test_replayed_numbers_give_the_same_spectral_image():
    scene = ps.scene_from_dict(scene_dict("cornell-box", (8, 8)))
    for estimator in ("pt", "bdpt"):
        recording = RecordingSamplers(StreamSamplers(2))
        first = ps.render(scene, estimator, spp=3, samplers=recording, spectral=True)
        again = ps.render(scene, estimator, spp=3, samplers=ReplaySamplers(recording.recording), spectral=True)
        np.testing.assert_array_equal(again.xyz, first.xyz)


def test_other_numbers_give_another_image():
    """The replay is not a cache: changing one recorded number changes the image."""
    scene = ps.scene_from_dict(scene_dict("cornell-box", (8, 8)))
    recording = RecordingSamplers(StreamSamplers(1))
    first = ps.render(scene, "pt", spp=1, samplers=recording)
    numbers = {key: recording.recording.numbers(key) for key in recording.recording.keys}
    numbers[(0, 0)][10, 0] = (numbers[(0, 0)][10, 0] + 0.5) % 1.0  # move lane 10's film position
    changed = ps.render(scene, "pt", spp=1, samplers=ReplaySamplers(numbers))
    assert not np.array_equal(changed.image, first.image)
