"""The film: per-pixel means and calibrated variances of the mean over the whole float range, non-finite samples
counted not added, passes assembled from splats and samples, films of disjoint passes merged."""
from __future__ import annotations

import pickle
from fractions import Fraction

import numpy as np
import pytest

import pathspace as ps
from pathspace import Film
from pathspace import film as film_module
from conftest import cornell_dict


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



# -- moments over the whole float range ------------------------------------------------------------------


@pytest.fixture(params=[None, 5], ids=["one-chunk", "chunks-of-5"])
def chunks(request, monkeypatch):
    """Run a test with the film's default chunking and with passes committed 5 pixels at a time."""
    if request.param is not None:
        monkeypatch.setattr(film_module, "CHUNK_PIXELS", request.param)


def exact_moments(samples) -> tuple[Fraction, Fraction]:
    """Mean and variance of the mean of float samples, in exact rational arithmetic."""
    xs = [Fraction(float(x)) for x in samples]
    n = len(xs)
    mean = sum(xs) / n
    return mean, sum((x - mean) ** 2 for x in xs) / (n * (n - 1))


def relative_error(value: float, exact: Fraction) -> float:
    """|value / exact - 1| computed exactly (exact != 0), rounded at the end."""
    return abs(float(Fraction(float(value)) / exact - 1))


EXTREME_PIXELS = np.array([
    [1e200, 2e200, 3e200, 4e200],          # beyond sqrt(float max): the naive sum of squares overflows
    [1e-200, 2e-200, 3e-200, 4e-200],      # squares below the smallest subnormal
    [1e-200, 1.0, 1e200, 2.0],             # every magnitude in one pixel
    [0.5, 0.25, 1.5, 3.0],                 # ordinary values
]).T                                        # (samples, pixels)


def test_moments_of_extreme_magnitudes_are_exact_to_rounding(chunks):
    """Means and standard errors of samples of 1e200, 1e-200 and both mixed with 1 in one pixel match
    exact rational arithmetic to a few ulps; the variance of the mean is exact where float64 can hold it
    and inf (0) where it lies beyond (below) float64's range."""
    film = Film(4, 3)
    samples = np.stack([np.stack([row, -3.0 * row, 0.5 * row]).repeat(3, axis=1) for row in EXTREME_PIXELS])
    for values in samples:  # (3 channels, 12 pixels): the four kinds of pixel, three times
        film.add_tile(0, values)
    mean = film.mean().transpose(2, 0, 1).reshape(3, 12)
    error = film.standard_error().transpose(2, 0, 1).reshape(3, 12)
    variance = film.variance().transpose(2, 0, 1).reshape(3, 12)
    assert np.isfinite(mean).all() and np.isfinite(error).all() and np.all(error > 0)
    for c in range(3):
        for p in range(12):
            exact_mean, exact_variance = exact_moments(samples[:, c, p])
            assert relative_error(mean[c, p], exact_mean) < 4e-16, (c, p)
            assert abs(float(Fraction(float(error[c, p])) ** 2 / exact_variance - 1)) < 4e-15, (c, p)
            if exact_variance > 1e308:
                assert variance[c, p] == np.inf
            elif exact_variance < 1e-320:
                assert variance[c, p] == 0.0
            else:
                assert relative_error(variance[c, p], exact_variance) < 4e-15, (c, p)
    assert film.nonfinite == 0 and np.all(film.count == 4)


def test_samples_near_1e8_keep_their_variance():
    """1e8 + unit noise: the one-pass (sum_sq - sum^2 / n) loses every digit, the film's updates do not."""
    rng = np.random.default_rng(2)
    samples = 1e8 + rng.normal(0.0, 1.0, size=(16, 1, 50))
    film = Film(50, 1, channels=1)
    for values in samples:
        film.add_tile(0, values)
    exact = np.array([float(exact_moments(samples[:, 0, p])[1]) for p in range(50)])
    np.testing.assert_allclose(film.variance()[0, :, 0], exact, rtol=1e-7)
    n = len(samples)
    naive = ((samples ** 2).sum(axis=0) - samples.sum(axis=0) ** 2 / n)[0] / (n * (n - 1))
    assert np.median(np.abs(naive / exact - 1)) > 0.3


def test_spectral_covariance_maps_to_srgb_exactly_at_any_scale():
    """A covariance film's sRGB variance is M C M^T of the exact XYZ covariance C, for samples of 1 and of
    1e200 alike (the standard error is compared where the variance is beyond float64's range)."""
    matrix = np.array([[3.24, -1.54, -0.50], [-0.97, 1.88, 0.04], [0.06, -0.20, 1.06]])
    rng = np.random.default_rng(5)
    xyz = rng.exponential(1.0, size=(6, 3, 4))
    for scale in (1.0, 1e200):
        film = Film(2, 2, covariance=True, to_srgb=matrix)
        for values in xyz * scale:
            film.add_tile(0, values)
        error = film.image_standard_error().transpose(2, 0, 1).reshape(3, 4)
        M = [[Fraction(float(v)) for v in row] for row in matrix]
        for p in range(4):
            columns = [[Fraction(float(v)) for v in sample[:, p]] for sample in xyz * scale]
            means = [sum(col[i] for col in columns) / 6 for i in range(3)]
            cov = [[sum((col[i] - means[i]) * (col[j] - means[j]) for col in columns) / 30 for j in range(3)]
                   for i in range(3)]
            for r in range(3):
                exact = sum(M[r][i] * cov[i][j] * M[r][j] for i in range(3) for j in range(3))
                assert abs(float(Fraction(float(error[r, p])) ** 2 / exact - 1)) < 1e-12, (scale, r, p)
        if scale == 1.0:
            np.testing.assert_allclose(film.image_variance(), error.reshape(3, 2, 2).transpose(1, 2, 0) ** 2,
                                       rtol=1e-14)


def run_passes(films, passes, splats, layers):
    """Hand pass k's splats, layer splats and samples to ``films[k]``."""
    for k, (values, (pixels, splat), named) in enumerate(zip(passes, splats, layers)):
        film = films[k]
        film.add_splats(k, pixels, splat)
        for name, (layer_pixels, layer_values) in named.items():
            film.add_splats(np.full(layer_pixels.size, k), layer_pixels, layer_values, layer=name)
        half = values.shape[1] // 2
        film.add_samples(k, 0, values[:, :half])
        film.add_samples(k, half, values[:, half:])


def test_merged_films_equal_the_film_of_all_their_passes(chunks):
    """Films of passes 0-4 and 5-11 merged (Chan's pairwise combination) equal the film of passes 0-11:
    counts, pass statistics and non-finite counts bit for bit, means and standard errors to a few ulps --
    with magnitudes from 1e-200 to 1e200 in one pixel, a NaN, and layers that only some passes reach."""
    rng = np.random.default_rng(7)
    pixels = 12
    passes = rng.exponential(1.0, size=(12, 3, pixels)) * 10.0 ** rng.choice([-200, 0, 200], size=(12, 1, pixels))
    passes[3, 1, 4] = np.nan
    splats = [(rng.integers(0, pixels, 5), rng.exponential(1.0, (3, 5))) for _ in range(12)]
    layers = [{"early": (rng.integers(0, pixels, 3), rng.exponential(1.0, (3, 3)))} if k < 3 else
              {"late": (rng.integers(0, pixels, 3), rng.exponential(1.0, (3, 3)))} if k >= 8 else {}
              for k in range(12)]
    whole, first, second = Film(4, 3), Film(4, 3), Film(4, 3)
    run_passes([whole] * 12, passes, splats, layers)
    run_passes([first] * 5 + [second] * 7, passes, splats, layers)
    first.merge(second)
    assert first.passes == whole.passes == 12 and first.nonfinite == whole.nonfinite == 1
    np.testing.assert_array_equal(first.count, whole.count)
    assert first.pass_peaks == whole.pass_peaks
    assert first.pass_relative_square_sums == whole.pass_relative_square_sums
    np.testing.assert_allclose(first.mean(), whole.mean(), rtol=1e-15)
    np.testing.assert_allclose(first.standard_error(), whole.standard_error(), rtol=1e-14)
    assert sorted(first.layers) == sorted(whole.layers) == ["early", "late"]
    for name in ("early", "late"):
        np.testing.assert_array_equal(first.layers[name].count, 12)
        np.testing.assert_allclose(first.layer_mean(name), whole.layer_mean(name), rtol=1e-15)
        np.testing.assert_allclose(first.layer_variance(name), whole.layer_variance(name), rtol=1e-13)
    # a layer reached in a few passes only has the mean and variance of its samples with zeros elsewhere
    late = np.zeros((12, 3, pixels))
    for k in range(8, 12):
        np.add.at(late[k].T, layers[k]["late"][0], layers[k]["late"][1].T)
    np.testing.assert_allclose(whole.layer_mean("late").transpose(2, 0, 1).reshape(3, -1), late.mean(axis=0),
                               rtol=1e-14)
    np.testing.assert_allclose(whole.layer_variance("late").transpose(2, 0, 1).reshape(3, -1),
                               late.var(axis=0, ddof=1) / 12, rtol=1e-12)


def test_splats_join_their_pass_in_arrival_order():
    """Splats for several passes in one call land in their own passes; within a pass they are summed in
    the order they arrive (0.1 + 1e16 - 1e16 = 0 in that order), then the pass's samples are added."""
    film = Film(3, 1, channels=1)
    film.add_splats(np.array([2, 0, 2, 1, 2]), np.array([0, 1, 0, 2, 0]), np.array([[0.1, 1.0, 1e16, 5.0, -1e16]]))
    assert film.incomplete_passes == [0, 1, 2]
    for k in range(3):
        film.add_samples(k, 0, np.full((1, 3), 2.0))
    assert film.passes == 3 and not film.incomplete_passes
    np.testing.assert_array_equal(film.sum[0], [6.0, 7.0, 11.0])  # pixel 0 of pass 2: 2 + (0.1 + 1e16 - 1e16)


def test_no_splats_open_no_pass():
    """Adding no splats, to a pass given as one int or per splat, opens neither the pass nor a layer."""
    film = Film(3, 1, channels=1)
    film.add_splats(4, np.array([], dtype=np.int64), np.zeros((1, 0)), layer="s1t1.weighted")
    film.add_splats(np.array([], dtype=np.int64), np.array([], dtype=np.int64), np.zeros((1, 0)))
    assert not film.incomplete_passes and not film.layers


def test_film_survives_pickling_mid_pass():
    """A film pickled with a pass open (as a resume file stores it) continues bit for bit."""
    rng = np.random.default_rng(3)
    film = Film(3, 2)
    film.add_samples(0, 0, rng.random((3, 6)))
    film.add_splats(1, np.array([1, 4]), rng.random((3, 2)), layer="s1t1.weighted")
    film.add_samples(1, 0, rng.random((3, 3)))
    copy = pickle.loads(pickle.dumps(film))
    rest = rng.random((3, 3))
    for f in (film, copy):
        f.add_samples(1, 3, rest)
    np.testing.assert_array_equal(copy.mean(), film.mean())
    np.testing.assert_array_equal(copy.variance(), film.variance())
    np.testing.assert_array_equal(copy.layer_mean("s1t1.weighted"), film.layer_mean("s1t1.weighted"))


def light_scaled(factor: float) -> ps.Scene:
    """The Cornell box at 12 x 12 with its light's radiance multiplied by ``factor``."""
    data = cornell_dict((12, 12))
    for shape in data["shapes"]:
        if "emitter" in shape:
            shape["emitter"]["radiance"] = [factor * v for v in shape["emitter"]["radiance"]]
    return ps.scene_from_dict(data)


@pytest.mark.parametrize("estimator", ["pt", "lt", "bdpt"])
def test_renders_of_extreme_radiance_are_finite_and_scale_exactly(estimator):
    """Lights of radiance 1e200 and 1e-200: finite images and standard errors, neither overflowing nor
    flushed to zero -- the radiance-1 render times the factor, to a few ulps -- and the same
    second-moment diagnostics."""
    reference = ps.render(light_scaled(1.0), estimator, spp=8, seed=1)
    lit = reference.image > 0
    assert lit.mean() > 0.9
    for factor in (1e200, 1e-200):
        result = ps.render(light_scaled(factor), estimator, spp=8, seed=1)
        error = result.film.image_standard_error()
        assert np.isfinite(result.image).all() and np.isfinite(error).all()
        assert np.all(result.image[lit] > 0) and np.all(error[reference.variance > 0] > 0)
        assert result.stats["nonfinite"] == 0 and result.stats["nonfinite_contributions"] == 0
        np.testing.assert_allclose(result.image / factor, reference.image, rtol=1e-14)
        np.testing.assert_allclose(error / factor, np.sqrt(reference.variance), rtol=1e-13)
        assert result.stats["largest_sample_share"] == pytest.approx(reference.stats["largest_sample_share"],
                                                                     rel=1e-12)
