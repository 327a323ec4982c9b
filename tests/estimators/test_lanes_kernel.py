"""The C kernel of a wavefront's compaction (ext/lanes.c) against numpy.take.

``Lanes.keep``, ``Walk.keep`` and ``Arrival.keep`` gather the lanes they keep with ``take_lanes``: NumPy's
``take(a, indices, axis=-1)`` of every array in one call.  Compared on every per-lane type (bool, int32,
int64, float32, float64, complex), one and two dimensions, arrays the loop does not handle (views with strides,
three dimensions, objects, byte-swapped: NumPy's take does those), repeated and empty index lists; then its
refusals.  Its inverse ``place_lanes`` (subpaths recorded depth by depth, flattened into lane order) against
NumPy's concatenation and fancy assignment: parts laid out as subpaths lay them (the kernel's windowed loop) and
permuted (its plain loop), mixed types and layouts of one field, then its refusals.  Last, ``useful_lanes`` (the
contributions worth weighting) against the NumPy expression it replaces, on extreme values.
"""
from __future__ import annotations

import numpy as np
import pytest

from pathspace import _native
from pathspace.estimators.wavefront import Lanes, place_lanes, take_lanes


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


# -- place_lanes: parts of a wavefront placed into one --------------------------------------------------------

def reference_place(positions: list[np.ndarray], parts: list[list[np.ndarray]]) -> list[np.ndarray]:
    """NumPy's way: each field's parts concatenated, then written to the positions."""
    at = np.concatenate(positions)
    out = []
    for column in zip(*parts):
        joined = np.concatenate(column, axis=-1)
        placed = np.empty_like(joined)
        placed[..., at] = joined
        out.append(placed)
    return out


def subpath_positions(rng: np.random.Generator, lanes: int) -> tuple[list[np.ndarray], int]:
    """Positions as subpaths recorded depth by depth have them: part i holds vertex i of the lanes longer than
    i, in lane order, and lane l's vertices are consecutive from offset[l] (increasing within every part)."""
    length = rng.geometric(0.3, lanes)
    offset = np.concatenate([[0], np.cumsum(length)])
    return [offset[:-1][length > i] + i for i in range(int(length.max()))], int(offset[-1])


def fields_of(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    return [rng.random(n) < 0.5, rng.integers(-100, 100, n, dtype=np.int8), rng.integers(-5, 5, n, dtype=np.int32),
            rng.integers(0, 1 << 40, n), rng.random((3, n)).astype(np.float32), rng.random((3, n)),
            rng.random((2, n)) + 1j * rng.random((2, n)), rng.random((1, n))]


@pytest.mark.parametrize("layout", ["subpaths", "permuted", "one part", "empty"])
def test_place_lanes_equals_numpy(layout):
    rng = np.random.default_rng(8)
    if layout == "subpaths":      # increasing within parts, over several of the kernel's windows
        positions, width = subpath_positions(rng, 3000)
    elif layout == "permuted":    # not increasing: placed part by part
        order = rng.permutation(5000)
        positions, width = np.split(order, [700, 2500, 2501]), 5000
    elif layout == "one part":
        positions, width = [rng.permutation(100)], 100
    else:
        positions, width = [np.zeros(0, np.int64), np.zeros(0, np.int64)], 0
    parts = [fields_of(rng, at.size) for at in positions]
    got = place_lanes(positions, parts)
    expected = reference_place(positions, parts)
    assert len(got) == len(expected)
    for a, b in zip(got, expected):
        assert a.dtype == b.dtype and a.shape == b.shape == b.shape[:-1] + (width,) and a.flags.c_contiguous
        np.testing.assert_array_equal(a, b)


def test_place_lanes_takes_the_type_concatenate_gives_and_any_layout():
    rng = np.random.default_rng(9)
    positions, width = subpath_positions(rng, 500)
    wide = [rng.random((3, 2 * at.size)) for at in positions]
    parts = [[rng.integers(0, 9, at.size, dtype=np.int32 if i % 2 else np.int64),        # mixed: int64
              rng.random(at.size).astype(np.float32 if i % 2 else np.float64),          # mixed: float64
              wide[i][:, ::2],                                                           # strided rows
              np.asfortranarray(rng.random((3, at.size))),
              rng.random(at.size).astype(">f8")]                                         # byte-swapped
             for i, at in enumerate(positions)]
    got = place_lanes([at.astype(np.int32) for at in positions], parts)
    expected = reference_place(positions, parts)
    for a, b in zip(got, expected):
        assert a.dtype == b.dtype.newbyteorder("=") and a.dtype.isnative
        np.testing.assert_array_equal(a, b)


def test_place_lanes_refuses_bad_arguments():
    a, b = np.zeros(3), np.zeros(2)
    two = [np.array([0, 2, 4]), np.array([1, 3])]
    with pytest.raises(ValueError, match=r"positions\[1\]\[1\] is outside 0 .. 4 or repeats"):
        _native.place_lanes([np.array([0, 2, 4]), np.array([1, 4])], [[a], [b]], 5)     # a lane twice
    with pytest.raises(ValueError, match=r"positions\[0\]\[0\] is outside"):
        _native.place_lanes([np.array([-1, 2, 4]), np.array([1, 3])], [[a], [b]], 5)
    with pytest.raises(ValueError, match=r"positions\[1\]\[1\] is outside 0 .. 4"):
        _native.place_lanes([np.array([0, 2, 4]), np.array([1, 5])], [[a], [b]], 5)
    with pytest.raises(ValueError, match="5 positions for a width of 6"):
        _native.place_lanes(two, [[a], [b]], 6)
    with pytest.raises(ValueError, match=r"positions\[0\]\[2\] is outside 0 .. 2"):
        place_lanes([np.array([0, 2, 4])], [[a]])     # three positions, not 0 .. 2
    with pytest.raises(ValueError, match=r"parts\[1\]\[0\] has 3 lanes, positions\[1\] 2"):
        _native.place_lanes(two, [[a], [a]], 5)
    with pytest.raises(ValueError, match=r"parts\[1\] has 2 fields, parts\[0\] 1"):
        _native.place_lanes(two, [[a], [b, b]], 5)
    with pytest.raises(ValueError, match="2 position lists for 1 parts"):
        _native.place_lanes(two, [[a]], 5)
    with pytest.raises(ValueError, match="at least one"):
        _native.place_lanes([], [], 0)
    with pytest.raises(TypeError, match=r"parts\[1\]\[0\] differs from parts\[0\]\[0\] in type or rows"):
        _native.place_lanes(two, [[a], [b.astype(np.float32)]], 5)
    with pytest.raises(TypeError, match=r"parts\[1\]\[0\] differs"):
        _native.place_lanes(two, [[np.zeros((2, 3))], [np.zeros((3, 2))]], 5)
    with pytest.raises(TypeError, match=r"parts\[0\]\[0\] is not a C-contiguous"):
        _native.place_lanes(two, [[np.zeros((1, 1, 3))], [np.zeros((1, 1, 2))]], 5)
    with pytest.raises(TypeError, match="C-contiguous, aligned, native bool or numeric"):
        place_lanes(two, [[np.array([None] * 3)], [np.array([None] * 2)]])
    with pytest.raises(TypeError, match=r"parts\[0\]\[0\] is not a NumPy array"):
        _native.place_lanes(two, [[[1.0, 2.0, 3.0]], [b]], 5)
    with pytest.raises(TypeError, match=r"positions\[p\] must be a 1D int64"):
        _native.place_lanes([np.array([0, 2, 4], np.int32), two[1]], [[a], [b]], 5)
    assert _native.place_lanes(two, [[], []], 5) == []


# -- useful_lanes ---------------------------------------------------------------------------------------------

def reference_useful(value: np.ndarray) -> tuple[np.ndarray, int]:
    """The NumPy code useful_lanes stands for: the columns finite in every row and not zero in some, and how
    many columns are not finite."""
    finite = np.isfinite(value).all(axis=0)
    return np.flatnonzero((value != 0).any(axis=0) & finite), int(finite.size - np.count_nonzero(finite))


@pytest.mark.parametrize("rows", [1, 3, 4])
def test_useful_lanes_equal_numpy(rows):
    """Values over 300 decades with zeros, negative zeros, infinities and NaNs, alone or beside finite values in
    a column; subnormals; columns of zeros."""
    rng = np.random.default_rng(rows)
    n = 5000
    value = 10.0 ** rng.uniform(-310, 300, (rows, n)) * rng.choice([-1.0, 1.0], (rows, n))
    for x, share in ((0.0, 0.3), (-0.0, 0.1), (np.inf, 0.01), (-np.inf, 0.01), (np.nan, 0.01)):
        value[rng.random((rows, n)) < share] = x
    value[:, rng.random(n) < 0.1] = 0.0
    lanes, nonfinite = _native.useful_lanes(value)
    expected, expected_nonfinite = reference_useful(value)
    np.testing.assert_array_equal(lanes, expected)
    assert lanes.dtype == np.int64 and nonfinite == expected_nonfinite
    assert 0 < lanes.size < n and nonfinite > 0 and (value[:, lanes] != 0).any(axis=0).all()


def test_useful_lanes_of_no_lanes_and_of_all():
    lanes, nonfinite = _native.useful_lanes(np.zeros((3, 0)))
    assert lanes.shape == (0,) and nonfinite == 0
    lanes, nonfinite = _native.useful_lanes(np.ones((3, 7)))
    np.testing.assert_array_equal(lanes, np.arange(7))
    assert nonfinite == 0


@pytest.mark.parametrize("value, error, match", [
    (np.ones((3, 4), np.float32), TypeError, "value"),
    (np.ones(4), TypeError, "value must be a 2D float64 array"),
    (np.ones((4, 3)).T, ValueError, "value"),
    ([[1.0, 2.0]], TypeError, "value"),
])
def test_useful_lanes_refuses_bad_arguments(value, error, match):
    with pytest.raises(error, match=match):
        _native.useful_lanes(value)
