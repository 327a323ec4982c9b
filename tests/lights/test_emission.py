"""Rays leaving the lights (the LightSet's ``sample_le``, ``pdf_le``, ``le`` over entities of every kind):
the densities a sample reports are those ``pdf_le`` gives its ray (pbrt's convention for lights at
infinity), its value is what ``le`` sends along it, and emitted rays estimate each finite light's power
without bias (E[value cos / (pdf_pos pdf_dir)] = the ``power`` light selection uses)."""
from __future__ import annotations

import numpy as np
import pytest

from pathspace.lights import DirectionalLight
from pathspace.mis import LIGHT_INFINITE
from pathspace.spectra import RGBColours
from lights.test_light_set import EVERY_KIND, two_light_scene


@pytest.mark.parametrize("selection", ["power", "uniform"])
def test_sample_le_densities_are_pdf_le(selection):
    scene = two_light_scene(EVERY_KIND)
    lights = scene.lights
    n = 50_000
    e = lights.sample_le(np.random.default_rng(3).random((5, n)), RGBColours, selection)
    assert set(np.unique(e.entity)) == set(range(lights.count))
    origin, direction = lights.pdf_le(e.entity, e.normal, e.direction, selection)
    pmf = lights.pmf(selection).take(e.entity)
    infinite = (lights.flags.take(e.entity) & LIGHT_INFINITE).astype(bool)
    np.testing.assert_array_equal(e.infinite, infinite)
    # Finite lights: (origin density with the pmf, direction density), as sampled.
    np.testing.assert_allclose(origin[~infinite], e.pdf_pos[~infinite], rtol=1e-6)
    np.testing.assert_allclose(direction[~infinite], e.pdf_dir[~infinite], rtol=1e-5)
    # Lights at infinity: the direction's density (with the pmf) first, the density on the disk second.
    np.testing.assert_allclose(origin[infinite], pmf[infinite] * e.pdf_dir[infinite], rtol=1e-12)
    np.testing.assert_allclose(direction[infinite], e.pdf_pos[infinite] / pmf[infinite], rtol=1e-12)
    # What a ray carries is what the light sends along it (radiance, intensity with the spot's falloff);
    # a directional light's rays carry its irradiance, while le (radiance toward a viewer) is 0.
    directional = lights.kind_of.take(e.entity) == lights.models.index(DirectionalLight)
    le = lights.le(e.entity, e.normal, e.direction, RGBColours)
    np.testing.assert_allclose(le[:, ~directional], e.value[:, ~directional], rtol=1e-12)
    assert not le[:, directional].any() and np.all(e.value[:, directional].T == [1, 2, 3])


def test_one_sided_area_lights_emit_on_their_normal_side_only():
    scene = two_light_scene()
    lights = scene.lights
    e = lights.sample_le(np.random.default_rng(4).random((5, 20_000)), RGBColours)
    cos = np.sum(e.normal * e.direction, axis=0)
    one_sided = ~lights.area.two_sided.take(e.entity)
    assert np.all(cos[one_sided] > 0) and np.any(cos[~one_sided] < 0) and np.any(cos[~one_sided] > 0)
    # Seen from behind, a one-sided lamp sends nothing and has no density of emitting that way.
    back = lights.le(e.entity, e.normal, -e.direction, RGBColours)
    assert not back[:, one_sided].any() and np.all(back[:, ~one_sided] > 0)
    assert not lights.pdf_le(e.entity, e.normal, -e.direction)[1][one_sided].any()


def test_emitted_rays_estimate_each_lights_power():
    """Per finite entity, the mean over its emitted rays of mean(value) cos / (pdf_pos pdf_dir / pmf)
    is its power: pi A Le (one-sided area), 2 pi A Le (two-sided), 4 pi I (point), and for the spot
    2 pi I ((1 - cos_start) + (cos_start - cos_cone) / 2), exact for a smoothstep in cos."""
    scene = two_light_scene(EVERY_KIND[:2])
    lights = scene.lights
    n = 400_000
    e = lights.sample_le(np.random.default_rng(5).random((5, n)), RGBColours, "uniform")
    pmf = lights.pmf("uniform").take(e.entity)
    estimate = e.value.mean(axis=0) * e.cos_light / (e.pdf_pos / pmf * e.pdf_dir)
    area = lights.area.area
    expected = np.array([np.pi * area[0], np.pi * area[1], 2 * np.pi * 8.0 * area[2], 2 * np.pi * 8.0 * area[3],
                         4 * np.pi * 2.0, 2 * np.pi * 5.0 * ((1 - np.cos(np.radians(20))) +
                                                           (np.cos(np.radians(20)) - np.cos(np.radians(30))) / 2)])
    np.testing.assert_allclose(lights.power, expected, rtol=1e-6)
    for entity in range(lights.count):
        mine = estimate[e.entity == entity]
        mean, error = mine.mean(), mine.std() / np.sqrt(mine.size)
        assert mine.size > 20_000 and abs(mean - expected[entity]) < 4 * error + 1e-9 * expected[entity], \
            (entity, mean, expected[entity], error)
