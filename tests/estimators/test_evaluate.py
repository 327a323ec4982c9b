"""The value of the paths made from given numbers (what Metropolis sampling and per-strategy studies
need) equals what the renderer adds to the film for the same numbers."""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace.estimators.bidirectional import STREAMS
from pathspace.sampler import RecordingSamplers, ReplaySampler, StreamSamplers
from pathspace.spectra import SpectralMode
from conftest import scene_dict


def recorded_pass(scene, estimator, **options):
    """A one-pass render (one work item: pass 0, tile 0) and the numbers it drew."""
    recording = RecordingSamplers(StreamSamplers(11))
    result = ps.render(scene, estimator, spp=1, samplers=recording, threads=1, **options)
    return result, recording.recording


@pytest.mark.parametrize("name", ["cornell-box", "cornell-box-specular", "veach-mis"])
def test_path_tracer_evaluates_the_renderers_samples(name):
    scene = ps.scene_from_dict(scene_dict(name, (16, 12)))
    result, recording = recorded_pass(scene, "pt")
    pixels = np.arange(scene.camera.pixel_count)
    values = ps.estimators.make_estimator("pt").evaluate(scene, pixels, ReplaySampler(recording.numbers((0, 0))))
    assert values.max() > 0
    np.testing.assert_array_equal(values, result.film.sum)


def test_path_tracer_evaluates_spectral_samples():
    scene = ps.scene_from_dict(scene_dict("cornell-box", (8, 8)))
    result, recording = recorded_pass(scene, "pt", spectral=True)
    pixels = np.arange(scene.camera.pixel_count)
    values = ps.estimators.make_estimator("pt").evaluate(scene, pixels, ReplaySampler(recording.numbers((0, 0))),
                                                          SpectralMode())
    np.testing.assert_array_equal(values, result.film.sum)


def test_path_tracer_evaluates_any_pixels_in_any_order():
    """Paths do not depend on their neighbours: a permutation of lanes permutes the values."""
    scene = ps.scene_from_dict(scene_dict("cornell-box", (8, 8)))
    numbers = np.random.default_rng(3).random((64, 400))
    pt = ps.estimators.make_estimator("pt", rr="off", max_depth=12)
    pixels = np.arange(64)
    values = pt.evaluate(scene, pixels, ReplaySampler(numbers))
    order = np.random.default_rng(4).permutation(64)
    np.testing.assert_array_equal(pt.evaluate(scene, pixels[order], ReplaySampler(numbers[order])), values[:, order])


@pytest.mark.parametrize("name, estimator", [("cornell-box", "bdpt"), ("cornell-box-thin-lens", "bdpt"),
                                             ("cornell-box-specular", "bdpt"), ("cornell-box-thin-lens", "lt")])
def test_bidirectional_strategies_add_up_to_the_renderers_samples(name, estimator):
    """Each lane's weighted own-pixel contributions plus all splats give the film's pass; each strategy's
    rows give its pyramid layer (weighted and unweighted)."""
    scene = ps.scene_from_dict(scene_dict(name, (12, 12)))
    result, recording = recorded_pass(scene, estimator, pyramid=3)
    samplers = {stream: ReplaySampler(recording.numbers((0, 0, code))) for stream, code in STREAMS.items()}
    pixels = np.arange(scene.camera.pixel_count)
    rows = ps.estimators.make_estimator(estimator, pyramid=3).evaluate(scene, pixels, samplers)
    assert rows.lane.size and np.all(rows.weight >= 0) and np.all(rows.weight <= 1 + 1e-12)
    image = np.zeros((3, pixels.size))
    for c in range(3):
        image[c] = np.bincount(rows.pixel, weights=rows.weighted[c], minlength=pixels.size)
    np.testing.assert_allclose(image, result.film.sum, rtol=1e-12, atol=1e-300)
    splat = np.isfinite(rows.raster[0])
    np.testing.assert_array_equal(rows.pixel[~splat], rows.lane[~splat])  # own pixels
    assert (estimator == "lt") == bool(splat.all())
    for (s, t), layers in result.strategies.items():
        pick = (rows.s == s) & (rows.t == t)
        for kind in ("weighted", "unweighted"):
            expected = np.zeros((3, pixels.size))
            for c in range(3):
                expected[c] = np.bincount(rows.pixel[pick], weights=getattr(rows, kind)[c, pick], minlength=pixels.size)
            np.testing.assert_allclose(expected, result.film.layers[f"s{s}t{t}.{kind}"].sum, rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(rows.weighted, rows.unweighted * rows.weight, rtol=1e-15)
