"""The C kernel of the film's moments (ext/film.c) against the NumPy code it replaces.

``Moments.add`` adds one sample to each of a run of pixels with ``_native.moments_add``; here the former
NumPy code (``reference_add``) is the reference, bit for bit, on samples over 600 decades (subnormal to
the largest float, so that exponents grow and stored moments are rescaled), zeros, columns with NaN or Inf, films of 1,
3 and 5 channels with and without covariance, runs of pixels inside the film and samples that are a column
range of a wider array; then the kernel's refusals.
"""
from __future__ import annotations

import numpy as np
import pytest

from pathspace import _native
from pathspace.film import Film, Moments, _exponents


def reference_add(moments: Moments, start: int, values: np.ndarray) -> np.ndarray:
    """The NumPy code of Moments.add before the kernel."""
    stop = start + values.shape[1]
    peak = np.abs(values).max(axis=0)
    finite = np.isfinite(peak)
    if finite.all():
        count, clean = 1, peak
    else:  # columns left out count no sample, and zeros in them change nothing else
        count, clean, values = finite, np.where(finite, peak, 0.0), np.where(finite, values, 0.0)
    exponent = moments._raise_exponent(start, stop, _exponents(clean))
    moments._combine(start, stop, count, values * np.ldexp(1.0, -exponent), None)
    return peak


def samples(rng: np.random.Generator, channels: int, n: int, bad: bool) -> np.ndarray:
    """Samples of random sign and magnitude 1e-320 .. 1e306 (a column shares its decade, as pixels do), some
    at 2^1023 or the largest float (exponents whose inverse power of two is subnormal), some zero, some
    (``bad``) NaN or +-Inf in one channel or all."""
    decade = rng.uniform(-320, 304, n)
    with np.errstate(over="ignore"):
        values = rng.choice([-1.0, 1.0], (channels, n)) * 10.0 ** (decade + rng.uniform(-2, 2, (channels, n)))
    values[np.isinf(values)] = np.finfo(float).max
    values[rng.random((channels, n)) < 0.01] = 2.0 ** 1023
    values[rng.random((channels, n)) < 0.01] = -np.finfo(float).max
    values[:, rng.random(n) < 0.1] = 0.0
    values[rng.random((channels, n)) < 0.05] = 0.0
    if bad:
        for value in (np.nan, np.inf, -np.inf):
            values[rng.integers(channels), rng.random(n) < 0.03] = value
        values[:, rng.random(n) < 0.01] = np.nan
    return values


def assert_same(kernel: Moments, reference: Moments) -> None:
    for name in ("count", "exponent", "scaled_mean", "scaled_m2"):
        np.testing.assert_array_equal(getattr(kernel, name), getattr(reference, name), err_msg=name)


@pytest.mark.parametrize("covariance", [False, True])
@pytest.mark.parametrize("channels", [1, 3, 5])
def test_moments_add_equals_the_numpy_reference(channels, covariance):
    rng = np.random.default_rng(channels * 2 + covariance)
    pixels = 3000
    kernel, reference = Moments(channels, pixels, covariance), Moments(channels, pixels, covariance)
    for k in range(12):   # successive samples: exponents grow and the stored moments are rescaled
        start = int(rng.integers(0, 500)) if k % 3 else 0
        n = pixels - start - int(rng.integers(0, 500))
        values = samples(rng, channels, n, bad=k % 2 == 1)
        if k % 4 == 2:   # a column range of a wider array: rows strided
            values = np.concatenate([values, np.ones((channels, 7))], axis=1)[:, :n]
        peak = kernel.add(start, values)
        np.testing.assert_array_equal(peak, reference_add(reference, start, values.copy()))
        assert_same(kernel, reference)
    assert (kernel.exponent > np.frexp(np.finfo(float).tiny)[1]).any() and (kernel.count < 12).any()


def test_moments_add_rescales_exactly_and_keeps_counts_of_left_out_columns():
    """Three samples of one pixel, the second 2**300 times the first, the third NaN: the pixel's
    mean and M2 are those of the two finite samples, and its count is 2."""
    moments = Moments(2, 1, covariance=False)
    moments.add(0, np.array([[3.0], [-1.0]]))
    moments.add(0, np.array([[3.0 * 2.0 ** 300], [0.0]]))
    peak = moments.add(0, np.array([[np.nan], [1.0]]))
    assert np.isnan(peak[0]) and moments.count[0] == 2
    mean = moments.mean(slice(0, 1))[:, 0]
    np.testing.assert_allclose(mean, [1.5 * (1.0 + 2.0 ** 300), -0.5], rtol=1e-15)
    variance = moments.variance(slice(0, 1))[:, 0]   # of the mean: M2 / (n (n - 1)) = (a - b)^2 / 4
    np.testing.assert_allclose(variance, [(3.0 * 2.0 ** 300 - 3.0) ** 2 / 4, 0.25], rtol=1e-15)


def test_film_commits_through_the_kernel_as_before():
    """A film's passes (an image and a layer) match the NumPy reference's moments bit for bit."""
    rng = np.random.default_rng(5)
    film, reference = Film(40, 30, 3), Moments(3, 1200, covariance=False)
    for k in range(5):
        values = samples(rng, 3, 1200, bad=k == 3)
        film.add_samples(k, 0, values)
        reference_add(reference, 0, values.copy())
    assert_same(film.moments, reference)
    assert film.passes == 5 and film.nonfinite == 1200 * 5 - reference.count.sum() > 0


def state(channels: int = 3, pixels: int = 10, covariance: bool = False):
    moments = Moments(channels, pixels, covariance)
    return [moments.count, moments.exponent, moments.scaled_mean, moments.scaled_m2]


@pytest.mark.parametrize("change, error, match", [
    (lambda a, v: (a[:1] + [a[1].astype(np.int64)] + a[2:], v), TypeError, "exponent"),
    (lambda a, v: (a[:2] + [a[2].astype(np.float32)] + a[3:], v), TypeError, "scaled_mean"),
    (lambda a, v: (a, v.astype(np.float32)), TypeError, "values"),
    (lambda a, v: (a, np.asfortranarray(np.ones((3, 4)))), ValueError, "values must be aligned, with contiguous rows"),
    (lambda a, v: (a, v[:2]), ValueError, "must agree"),
    (lambda a, v: (a[:3] + [np.zeros((3, 10))[:, :9].copy()], v), ValueError, "must agree"),
    (lambda a, v: (a[:3] + [np.zeros((3, 2, 10))], v), ValueError, "must agree"),
    (lambda a, v: (a[:3] + [np.zeros((2, 10))], v), ValueError, "must agree"),
    (lambda a, v: (a[:1] + [a[1][:9].copy()] + a[2:], v), ValueError, "must agree"),
    (lambda a, v: (a[:2] + [np.zeros((3, 9))] + a[3:], v), ValueError, "must agree"),
    (lambda a, v: ([a[0][:0].copy(), a[1][:0].copy(), np.zeros((0, 0)), np.zeros((0, 0))], np.zeros((0, 0))),
     ValueError, "must agree"),
    (lambda a, v: (a, v.astype(v.dtype.newbyteorder())), TypeError, "values"),
    (lambda a, v: (a, np.frombuffer(np.zeros(97, np.uint8).data, np.float64, 12, 1).reshape(3, 4)), ValueError,
     "values must be aligned"),
    (lambda a, v: (a, np.lib.stride_tricks.as_strided(np.zeros(8), (3, 1), (12, 8))), ValueError,
     "values must be aligned"),
])
def test_moments_add_refuses_bad_arguments(change, error, match):
    arrays, values = change(state(), np.ones((3, 4)))
    with pytest.raises(error, match=match):
        _native.moments_add(*arrays, 0, values)


@pytest.mark.parametrize("start", [-1, 7, 11])
def test_moments_add_refuses_pixels_outside_the_film(start):
    with pytest.raises(ValueError, match="outside the film"):
        _native.moments_add(*state(), start, np.ones((3, 4)))


def test_film_takes_samples_of_any_layout():
    """Transposed, misaligned and float32 samples reach the kernel as copies: the moments are those of the
    same samples as a float64 C array."""
    rng = np.random.default_rng(9)
    image = rng.random((600, 3))
    buffer = np.zeros(image.size * 8 + 1, np.uint8)
    misaligned = np.frombuffer(buffer.data, np.float64, image.size, 1).reshape(3, 600)
    misaligned[...] = image.T
    films = [Film(30, 20, 3) for _ in range(4)]
    for film, values in zip(films, (np.ascontiguousarray(image.T), image.T, misaligned, image.T)):
        film.add_samples(0, 0, values)
    films[3].add_samples(1, 0, image.T.astype(np.float32))
    films[0].add_samples(1, 0, image.T.astype(np.float32).astype(np.float64))
    for film in films[1:3]:
        film.add_samples(1, 0, image.T.astype(np.float32).astype(np.float64))
    for film in films[1:]:
        assert_same(film.moments, films[0].moments)


def test_moments_add_refuses_read_only_state():
    arrays = state()
    arrays[3].flags.writeable = False
    with pytest.raises(ValueError, match="scaled_m2 must be writeable"):
        _native.moments_add(*arrays, 0, np.ones((3, 4)))


def test_splat_add_equals_np_add_at():
    """Splats of a pass (many on the same pixels, over 600 decades, NaN and Inf among them) land in the
    buffer as np.add.at per channel puts them, bit for bit: the same additions in the same order."""
    rng = np.random.default_rng(11)
    for channels in (1, 3, 4):
        buffer = samples(rng, channels, 500, bad=False)
        reference = buffer.copy()
        for bad in (False, True):
            pixels = rng.integers(0, 40, 5000)   # ~125 splats per pixel: their order matters
            values = samples(rng, channels, pixels.size, bad)
            if bad:   # a column range of a wider array: rows strided
                values = np.concatenate([values, np.ones((channels, 3))], axis=1)[:, :pixels.size]
            _native.splat_add(buffer, pixels, values)
            with np.errstate(over="ignore", invalid="ignore"):
                for c in range(channels):
                    np.add.at(reference[c], pixels, values[c])
            np.testing.assert_array_equal(buffer, reference)
    assert np.isnan(buffer).any() and np.isfinite(buffer).any()


def test_film_splats_of_any_layout():
    """Transposed, misaligned and float32 values and int32 pixels reach the kernel as copies: the film's pass
    is the one the same splats as float64 and int64 C arrays give."""
    rng = np.random.default_rng(12)
    pixels = rng.integers(0, 600, 2000)
    values = rng.random((2000, 3)).astype(np.float32).astype(np.float64)   # float32 holds them exactly
    raw = np.zeros(values.size * 8 + 1, np.uint8)
    misaligned = np.frombuffer(raw.data, np.float64, values.size, 1).reshape(3, 2000)
    misaligned[...] = values.T
    layouts = [(pixels, np.ascontiguousarray(values.T)), (pixels, values.T), (pixels.astype(np.int32), misaligned),
               (pixels, values.T.astype(np.float32))]
    films = [Film(30, 20, 3) for _ in layouts]
    for film, (p, v) in zip(films, layouts):
        film.add_splats(0, p, v)
        film.add_samples(0, 0, np.zeros((3, 600)))
    for film in films[1:]:
        assert_same(film.moments, films[0].moments)
    assert films[0].moments.count.sum() == 600 and (films[0].moments.scaled_mean > 0).any()


@pytest.mark.parametrize("buffer, pixels, values, error, match", [
    (np.zeros((3, 10), np.float32), np.zeros(2, np.int64), np.ones((3, 2)), TypeError, "buffer"),
    (np.zeros((3, 10)), np.zeros(2, np.int32), np.ones((3, 2)), TypeError, "pixels"),
    (np.zeros((3, 10)), np.zeros(2, np.int64), np.ones((3, 2), np.float32), TypeError, "values"),
    (np.zeros((3, 10)), np.zeros(2, np.int64), np.ones((2, 2)), ValueError, r"expected \(3, 2\)"),
    (np.zeros((3, 10)), np.zeros(3, np.int64), np.ones((3, 2)), ValueError, r"expected \(3, 3\)"),
    (np.zeros((3, 10)), np.array([0, 10]), np.ones((3, 2)), IndexError, "pixel 10 of splat 1 is outside the film"),
    (np.zeros((3, 10)), np.array([-1, 0]), np.ones((3, 2)), IndexError, "pixel -1 of splat 0"),
])
def test_splat_add_refuses_bad_arguments(buffer, pixels, values, error, match):
    before = buffer.copy()
    with pytest.raises(error, match=match):
        _native.splat_add(buffer, pixels, values)
    np.testing.assert_array_equal(buffer, before)   # nothing added before the refusal


def test_splat_add_refuses_a_read_only_buffer():
    buffer = np.zeros((3, 10))
    buffer.flags.writeable = False
    with pytest.raises(ValueError, match="buffer must be writeable"):
        _native.splat_add(buffer, np.zeros(1, np.int64), np.ones((3, 1)))
