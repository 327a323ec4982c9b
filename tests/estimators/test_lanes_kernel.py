"""The C kernel of a wavefront's compaction (ext/lanes.c) against numpy.take.

``Lanes.keep``, ``Walk.keep`` and ``Arrival.keep`` gather the lanes they keep with ``take_lanes``: NumPy's
``take(a, indices, axis=-1)`` of every array in one call.  Compared on every per-lane type (bool, int32,
int64, float32, float64, complex), one and two dimensions, arrays the loop does not handle (views with strides,
three dimensions, objects, byte-swapped: NumPy's take does those), repeated and empty index lists; then its
refusals.
"""
from __future__ import annotations

import numpy as np
import pytest

from pathspace import _native
from pathspace.estimators.wavefront import Lanes, take_lanes


def arrays(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    wide = rng.random((3, 2 * n))
    return [rng.random(n) < 0.5, rng.integers(-5, 5, n, dtype=np.int32), rng.integers(0, 1 << 40, n),
            rng.random((3, n)).astype(np.float32), rng.random((4, n)), rng.random((2, n)) + 1j * rng.random((2, n)),
            wide[:, ::2], np.asfortranarray(rng.random((3, n))), rng.random((2, 3, n)),
            np.array([object()] * n, dtype=object), rng.random(n).astype(">f8"), rng.random((1, n))]


@pytest.mark.parametrize("pick", ["some", "all", "none", "repeated"])
def test_take_lanes_equals_numpy_take(pick):
    rng = np.random.default_rng(3)
    n = 1000
    given = arrays(rng, n)
    indices = {"some": np.flatnonzero(rng.random(n) < 0.6), "all": np.arange(n), "none": np.zeros(0, np.int64),
               "repeated": rng.integers(0, n, 2 * n)}[pick]
    got = take_lanes(indices, *given)
    assert len(got) == len(given)
    for a, b in zip(got, given):
        expected = np.take(b, indices, axis=-1)
        assert a.dtype == expected.dtype and a.shape == expected.shape
        if b.dtype == object:
            assert all(x is y for x, y in zip(a, expected))
        else:
            np.testing.assert_array_equal(a, expected)
            assert a.flags.c_contiguous


def test_lanes_keep_and_split_keep_their_fields_in_order():
    rng = np.random.default_rng(4)
    fields = ("depth", "origin", "beta", "delta")
    values = {"depth": np.arange(10, dtype=np.int32), "origin": rng.random((3, 10)).astype(np.float32),
              "beta": rng.random((3, 10)), "delta": rng.random(10) < 0.5}
    lanes = Lanes(fields, **values)
    part = lanes.split(np.array([1, 4, 7]))
    np.testing.assert_array_equal(part.depth, [1, 4, 7])
    np.testing.assert_array_equal(part.beta, values["beta"][:, [1, 4, 7]])
    np.testing.assert_array_equal(lanes.depth, [0, 2, 3, 5, 6, 8, 9])
    lanes.keep(np.array([0, 2, 5]))                  # of the lanes left: 0, 3 and 8
    np.testing.assert_array_equal(lanes.depth, [0, 3, 8])
    np.testing.assert_array_equal(lanes.origin, values["origin"][:, [0, 3, 8]])
    np.testing.assert_array_equal(lanes.delta, values["delta"][[0, 3, 8]])


def test_take_lanes_refuses_bad_arguments():
    a, b = np.zeros(5), np.zeros((2, 6))
    with pytest.raises(IndexError, match=r"indices\[1\] = 5 is outside 0 .. 4"):
        _native.take_lanes(np.array([0, 5]), [a])
    with pytest.raises(IndexError, match=r"indices\[0\] = -1"):
        _native.take_lanes(np.array([-1]), [a, a])
    with pytest.raises(ValueError, match="arrays\\[1\\] has 6 lanes, arrays\\[0\\] 5"):
        _native.take_lanes(np.array([0]), [a, b])
    with pytest.raises(TypeError, match="indices must be a 1D int64"):
        _native.take_lanes(np.array([0], np.int32), [a])
    with pytest.raises(TypeError, match="Cannot cast"):
        take_lanes(np.array([0.5]), a)                       # np.take refuses float indices too
    np.testing.assert_array_equal(take_lanes(np.array([2, 0], np.int32), a)[0], a[[2, 0]])
    with pytest.raises(TypeError, match="is not a NumPy array"):
        _native.take_lanes(np.array([0]), [a, [1.0]])
    with pytest.raises(TypeError):
        _native.take_lanes(np.array([0]), (a,))
    assert _native.take_lanes(np.array([0]), []) == []
