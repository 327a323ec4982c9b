"""Film statistics, EXR/PNG files and the error metrics."""
from __future__ import annotations

import numpy as np
import pytest

from pathspace import Film, metrics
from pathspace.imageio import read_exr, to_srgb8, write_exr, write_png


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


def test_exr_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    image = rng.random((5, 7, 3)) * 100
    variance = rng.random((5, 7, 3))
    write_exr(tmp_path / "a.exr", image, variance, {"spp": 64, "estimator": "pt", "params": {"rr": "off"}})
    back, back_var, meta = read_exr(tmp_path / "a.exr")
    np.testing.assert_array_equal(back, image.astype(np.float32))
    np.testing.assert_array_equal(back_var, variance.astype(np.float32))
    assert meta == {"spp": 64, "estimator": "pt", "params": {"rr": "off"}}
    # A strided view (not contiguous) is written correctly too.
    write_exr(tmp_path / "b.exr", image[:, ::-1])
    np.testing.assert_array_equal(read_exr(tmp_path / "b.exr")[0], image[:, ::-1].astype(np.float32))


def test_exr_errors(tmp_path):
    with pytest.raises(ValueError, match=r"shape \(height, width, 3\)"):
        write_exr(tmp_path / "x.exr", np.zeros((4, 4)))
    with pytest.raises(FileNotFoundError):
        read_exr(tmp_path / "none.exr")
    (tmp_path / "bad.exr").write_bytes(b"not an exr")
    with pytest.raises(ValueError, match="cannot read as OpenEXR"):
        read_exr(tmp_path / "bad.exr")


def test_png_encoding(tmp_path):
    # sRGB OETF: 0 -> 0, 0.5 -> 188 (0.7354), 1 -> 255, and exposure doubles per stop.
    image = np.array([[[0.0, 0.5, 1.0], [0.25, 2.0, np.nan]]])
    np.testing.assert_array_equal(to_srgb8(image), [[[0, 188, 255], [137, 255, 0]]])
    np.testing.assert_array_equal(to_srgb8(image[:, :1] * 0 + 0.25, exposure=1.0), to_srgb8(image[:, :1] * 0 + 0.5))
    write_png(tmp_path / "x.png", image)
    from PIL import Image

    np.testing.assert_array_equal(np.asarray(Image.open(tmp_path / "x.png")), to_srgb8(image))


def test_metrics():
    ref = np.full((2, 2, 3), 1.0)
    test = ref.copy()
    test[0, 0, 0] = 2.0
    assert metrics.mse(test, ref) == pytest.approx(1 / 12)
    assert metrics.rmse(test, ref) == pytest.approx(np.sqrt(1 / 12))
    assert metrics.relmse(test, ref) == pytest.approx(1 / 12 / 1.01)
    with pytest.raises(ValueError, match="differ in shape"):
        metrics.mse(test, ref[:1])
