"""Strategy studies: per-strategy variance and MIS-weight images, error images, posterize."""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace.experiment import posterize, relative_error, strategy_images, weight_images, z_scores
from conftest import scene_dict


def test_strategy_images_have_variances_and_weights():
    scene = ps.scene_from_dict(scene_dict("cornell-box", (16, 16)))
    result = ps.render(scene, "bdpt", spp=64, seed=1, pyramid=2, max_depth=2)
    images = strategy_images(result)
    assert set(images) == {(0, 2), (1, 1), (2, 0), (0, 3), (1, 2), (2, 1), (3, 0)} - {(2, 0), (3, 0)}
    for (s, t), entry in images.items():
        weight = entry["weight"][np.isfinite(entry["weight"])]
        assert np.all(weight >= -1e-12) and np.all(weight <= 1 + 1e-12)
        variance = entry["weighted_variance"]
        assert np.all(variance >= 0) and np.isfinite(variance).all()
    # the weighted strategy images of every path length add up to the image (max_depth = pyramid)
    total = sum(entry["weighted"] for entry in images.values())
    np.testing.assert_allclose(total, result.image, rtol=1e-9, atol=1e-12)
    # the variance of a strategy image is the variance of its mean over the passes
    film = result.film
    layer = film.layers["s1t2.weighted"]
    n = film.passes
    expected = (layer.sum_sq - layer.sum ** 2 / n) / (n * (n - 1))
    np.testing.assert_allclose(images[(1, 2)]["weighted_variance"].transpose(2, 0, 1).reshape(3, -1),
                               np.maximum(expected, 0), rtol=1e-9, atol=1e-15)
    assert set(weight_images(result)) == set(images)


def test_error_images():
    reference = np.full((2, 2, 3), 0.5)
    test = reference + np.array([0.1, -0.1, 0.0])
    np.testing.assert_allclose(relative_error(test, reference, epsilon=0.0)[0, 0], [0.2, -0.2, 0.0])
    z = z_scores(test, np.full_like(test, 0.01), reference)
    np.testing.assert_allclose(z[0, 0], [1.0, -1.0, 0.0])
    assert np.isposinf(z_scores(test, np.zeros_like(test), reference)[0, 0, 0])


def test_posterize():
    ramp = np.linspace(0, 1, 100)[None, :, None].repeat(3, axis=2)
    levels = np.unique(posterize(ramp, 4))
    np.testing.assert_allclose(levels, [0, 1 / 3, 2 / 3, 1])
    with pytest.raises(ValueError, match="levels"):
        posterize(ramp, 1)
