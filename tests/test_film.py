"""The film: per-pixel means and calibrated variances of the mean, non-finite samples counted not added."""
from __future__ import annotations

import numpy as np

from pathspace import Film


def test_film_mean_and_variance_of_the_mean():
    rng = np.random.default_rng(0)
    film = Film(4, 3)
    samples = rng.exponential(2.0, size=(50, 3, 12))
    for s in samples:
        film.add_tile(0, s)
    np.testing.assert_allclose(film.mean().transpose(2, 0, 1).reshape(3, 12), samples.mean(axis=0))
    expected_var = samples.var(axis=0, ddof=1) / 50
    np.testing.assert_allclose(film.variance().transpose(2, 0, 1).reshape(3, 12), expected_var, rtol=1e-10)


def test_variance_estimate_is_calibrated():
    """Across many pixels, z-scores of the means follow Student's t with 15 dof (std sqrt(15/13))."""
    rng = np.random.default_rng(1)
    film = Film(100, 100, channels=1)
    for _ in range(16):
        film.add_tile(0, rng.uniform(0.0, 2.0, size=(1, 10_000)))
    z = (film.mean() - 1.0) / np.sqrt(film.variance())
    assert abs(z.std() - np.sqrt(15 / 13)) < 0.03


def test_nonfinite_samples_are_counted_not_added():
    film = Film(2, 2)
    values = np.ones((3, 4))
    values[1, 2] = np.nan
    values[0, 3] = np.inf
    film.add_tile(0, values)
    film.add_tile(0, np.ones((3, 4)))
    assert film.nonfinite == 2
    assert np.all(np.isfinite(film.mean()))
    np.testing.assert_array_equal(film.count, [2, 2, 1, 1])  # the failed samples are not counted
    np.testing.assert_allclose(film.mean(), 1.0)


def test_variance_is_infinite_below_two_samples():
    film = Film(2, 1)
    film.add_tile(0, np.ones((3, 2)))
    assert np.all(np.isinf(film.variance()))

