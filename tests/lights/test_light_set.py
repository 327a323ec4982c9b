"""The LightSet's verbs over entities, for light sampling from a receiver: selection pmfs, ``sample_li``
against ``pdf_li`` (area and solid-angle measure, power and uniform selection), unbiased subtended
solid angles (one-sided lamps seen from behind carry nothing), delta and environment samples, entity
flags, and a chi-square test of sampled directions against the densities ``pdf_li`` gives."""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace.lights import DirectionalLight, Environment, PointLight, SpotLight
from pathspace.mis import LIGHT_DELTA, LIGHT_INFINITE
from pathspace.spectra import RGBColours
from pathspace.validate import chi2_test_directions
from conftest import cornell_dict


def two_light_scene(extra_lights=()):
    """The Cornell box with its one-sided ceiling lamp and a small two-sided lamp near the back wall."""
    data = cornell_dict((8, 8))
    data["shapes"][0]["emitter"] = {"radiance": [1.0] * 3}
    data["shapes"].append({"name": "lamp2", "type": "quad", "corner": [-0.9, -0.5, -0.99], "edge_u": [0.3, 0, 0],
                           "edge_v": [0, 0.2, 0], "material": "white",
                           "emitter": {"radiance": [8.0] * 3, "two_sided": True}})
    data["lights"] = list(extra_lights)
    data["render"] = {"origin": [0.0, 0.0, 0.0]}  # render space = world space: receivers below are world points
    return ps.scene_from_dict(data)


EVERY_KIND = [{"type": "point", "position": [0, 0.5, 0], "intensity": [2, 2, 2]},
              {"type": "spot", "position": [0, 0.9, 0], "look_at": [0, -1, 0], "intensity": [5, 5, 5],
               "cone_angle": 30, "falloff_start": 20},
              {"type": "directional", "direction": [0, -1, 0], "irradiance": [1, 2, 3]},
              {"type": "environment", "radiance": [0.1, 0.2, 0.3]}]


def spherical_triangle_omega(v, point):
    p = v - point
    a, b, c = p
    numerator = np.dot(a, np.cross(b, c))
    la, lb, lc = np.linalg.norm(p, axis=1)
    denominator = la * lb * lc + np.dot(a, b) * lc + np.dot(a, c) * lb + np.dot(b, c) * la
    return abs(2 * np.arctan2(numerator, denominator))


@pytest.mark.parametrize("measure", ["area", "solid_angle"])
@pytest.mark.parametrize("selection", ["power", "uniform"])
def test_sample_li_density_is_pdf_li(selection, measure):
    """The density sample_li reports is the one pdf_li gives the point a ray finds, on the entity the
    ray hits (for area lights the entity of a triangle is ``area.emitter_of_triangle[triangle]``)."""
    scene = two_light_scene()
    lights = scene.lights
    rng = np.random.default_rng(0)
    receivers = rng.uniform(-0.8, 0.8, (3, 20_000)).astype(np.float32)
    s = lights.sample_li(receivers, rng.random((3, 20_000)), RGBColours, selection, measure)
    # Recover the sampled triangle by tracing the sampled direction.
    hits = scene.accel.intersect(receivers, s.wi)
    entity = np.where(hits.prim >= 0, lights.area.emitter_of_triangle[np.maximum(hits.prim, 0)], -1)
    reached = np.isclose(hits.t, s.distance, rtol=1e-4) & (entity >= 0)
    assert reached.sum() > 2000  # unoccluded samples to compare (receivers may sit inside the boxes)
    np.testing.assert_array_equal(s.entity[reached], entity[reached])  # the sample lies on the entity it names
    points = receivers[:, reached] + s.wi[:, reached] * s.distance[reached]
    again = lights.pdf_li(entity[reached], receivers[:, reached], points, selection, measure)
    np.testing.assert_allclose(again, s.pdf[reached], rtol=2e-3)


@pytest.mark.parametrize("measure", ["area", "solid_angle"])
def test_light_sampling_integrates_the_subtended_solid_angle(measure):
    """E[1 / pdf] over light samples (pmf included) = the total solid angle of the lights seen from a point.

    One receiver in front of the one-sided ceiling lamp, one behind it (above the lamp plane, where it sees
    the lamp's back): samples of the back side must carry no radiance.
    """
    scene = two_light_scene()
    lights = scene.lights
    for point, lamp_visible in ((np.array([0.1, -0.3, 0.2]), True), (np.array([0.0, 0.995, 0.0]), False)):
        n = 400_000
        s = lights.sample_li(np.repeat(point[:, None].astype(np.float32), n, axis=1),
                             np.random.default_rng(1).random((3, n)), RGBColours, "power", measure)
        emitting = s.facing & (s.value[0] > 0)
        estimate = np.where(emitting, 1.0 / s.pdf, 0.0)
        mean, error = estimate.mean(), estimate.std() / np.sqrt(n)
        exact = 0.0
        for e, tri in enumerate(lights.area.triangles):
            v = scene.mesh.vertices[scene.mesh.indices[tri]]
            facing = np.dot(scene.mesh.normal[:, tri], point - v.mean(axis=0)) > 0
            if lights.area.two_sided[e] or facing:
                exact += spherical_triangle_omega(v, point)
        assert abs(mean - exact) < 4 * error + 1e-12, (point, mean, exact, error)
        if not lamp_visible:
            # Samples on the one-sided ceiling lamp (normal -y) seen from above reach its back: no radiance.
            on_lamp = s.normal[1] < -0.5
            assert on_lamp.sum() > 1000 and not np.any(emitting & on_lamp)


def test_selection_pmfs():
    scene = two_light_scene(EVERY_KIND[:1] + EVERY_KIND[3:])
    lights = scene.lights
    power = lights.power
    np.testing.assert_allclose(lights.pmf("power"), power / power.sum())
    np.testing.assert_allclose(np.bincount(lights.light_id, weights=lights.pmf("uniform")), [0.25] * 4)
    np.testing.assert_allclose(power[-2], 4 * np.pi * 2.0)  # point: 4 pi I
    with pytest.raises(ValueError, match="light selection: expected one of"):
        lights.pmf("random")


def test_entities_flags_and_models():
    """Entities: the 4 emitting triangles first, then one per other light in the order point, spot,
    directional, environment; their flags say which no ray can hit and which lie at infinity."""
    scene = two_light_scene(EVERY_KIND)
    lights = scene.lights
    assert lights.count == 8 and lights.area.count == 4 and lights.has_delta
    np.testing.assert_array_equal(lights.flags, [0, 0, 0, 0, LIGHT_DELTA, LIGHT_DELTA, LIGHT_DELTA | LIGHT_INFINITE,
                                                 LIGHT_INFINITE])
    np.testing.assert_array_equal(lights.light_id, [0, 0, 1, 1, 2, 3, 4, 5])
    assert [model.kind for model in lights.models] == ["area", "point", "spot", "directional", "environment"]
    assert lights.environment_entity == 7 and isinstance(lights.environment, Environment)
    assert lights.environment.radiance == (0.1, 0.2, 0.3)
    assert [type(light) for light in lights.lights[2:]] == [PointLight, SpotLight, DirectionalLight, Environment]
    np.testing.assert_array_equal(lights.area.emitter_of_triangle[lights.area.triangles], np.arange(4))
    assert np.count_nonzero(lights.area.emitter_of_triangle >= 0) == 4
    without = two_light_scene().lights
    assert without.environment is None and without.environment_entity == -1 and not without.has_delta


def test_delta_and_environment_samples():
    scene = two_light_scene(EVERY_KIND)
    lights = scene.lights
    receiver = np.array([[0.0], [-0.5], [0.0]], dtype=np.float32)
    n = 100_000
    s = lights.sample_li(np.repeat(receiver, n, axis=1), np.random.default_rng(2).random((3, n)), RGBColours,
                         "uniform")
    point = np.isclose(s.distance, 1.0) & s.delta
    np.testing.assert_allclose(s.value[:, point], 2.0)                 # I / d^2, d = 1
    np.testing.assert_allclose(s.wi[:, point].T, [[0, 1, 0]] * point.sum(), atol=1e-6)
    spot = np.isclose(s.distance, 1.4) & s.delta
    np.testing.assert_allclose(s.value[:, spot], 5.0 / 1.4 ** 2, rtol=1e-5)  # on axis: full intensity
    directional = s.delta & np.isinf(s.distance)
    np.testing.assert_allclose(s.value[:, directional].T, [[1, 2, 3]] * directional.sum())
    env = ~s.delta & np.isinf(s.distance)
    np.testing.assert_allclose(s.pdf[env], 1 / 6 / (4 * np.pi))          # uniform selection among 6 lights
    assert abs(point.mean() - 1 / 6) < 0.01 and abs(env.mean() - 1 / 6) < 0.01
    np.testing.assert_array_equal(s.entity[point], 4)
    np.testing.assert_array_equal(s.entity[spot], 5)
    np.testing.assert_array_equal(s.entity[directional], 6)
    np.testing.assert_array_equal(s.entity[env], lights.environment_entity)
    # The environment through the entity verbs: radiance le, density pdf_li (pmf / 4 pi) in any direction.
    entity = np.full(3, lights.environment_entity)
    directions = np.eye(3)
    np.testing.assert_allclose(lights.le(entity, directions, directions, RGBColours).T, [[0.1, 0.2, 0.3]] * 3)
    np.testing.assert_allclose(lights.pdf_li(entity, np.zeros((3, 3)), directions, "uniform"), 1 / 6 / (4 * np.pi))
    # Spot falloff (its SpotLight description and its tables): zero beyond the cone, smoothstep inside.
    spot_light = next(light for light in lights.lights if isinstance(light, SpotLight))
    assert (spot_light.cone_angle, spot_light.falloff_start) == (30, 20)
    tables = lights.tables[lights.models.index(SpotLight)]
    dirs = np.array([[0, -1, 0], [np.sin(np.radians(25)), -np.cos(np.radians(25)), 0],
                     [np.sin(np.radians(31)), -np.cos(np.radians(31)), 0]]).T
    falloff = tables.falloff(np.zeros(3, np.int64), dirs)
    assert falloff[0] == 1.0 and 0 < falloff[1] < 1 and falloff[2] == 0.0
    x = (np.cos(np.radians(25)) - spot_light.cos_cone) / (spot_light.cos_falloff_start - spot_light.cos_cone)
    assert falloff[1] == pytest.approx(x * x * (3 - 2 * x), rel=1e-12)
    np.testing.assert_allclose(lights.le(np.full(3, 5), np.zeros((3, 3)), dirs, RGBColours),
                               np.repeat(5.0 * falloff[None], 3, axis=0))


@pytest.mark.parametrize("measure", ["area", "solid_angle"])
@pytest.mark.parametrize("selection", ["power", "uniform"])
def test_light_sampling_directions_chi2(selection, measure):
    """Directions of light samples from a receiver, against the density pdf_li gives the surface they reach."""
    scene = two_light_scene([{"type": "environment", "radiance": [0.1, 0.1, 0.1]}])
    lights = scene.lights
    receiver = np.array([[0.2], [-0.3], [0.1]], dtype=np.float32)

    def sample(u):
        s = lights.sample_li(np.repeat(receiver, u.shape[1], axis=1), u, RGBColours, selection, measure)
        return s.wi, np.ones(u.shape[1], bool)

    def pdf(directions):
        """Sum over every emitting triangle on the line of each direction (and the environment)."""
        count = directions.shape[1]
        origins = np.repeat(receiver, count, axis=1)
        total = lights.pdf_li(np.full(count, lights.environment_entity), origins, directions, selection, measure)
        emitters = scene.emitter_accel
        tmin = np.zeros(count, dtype=np.float32)
        lanes = np.arange(count)
        d = directions.astype(np.float32)
        while lanes.size:
            h = emitters.intersect(origins[:, lanes], d[:, lanes], tmin[lanes], np.inf, normals=False)
            found = h.prim >= 0
            lanes, prim, t = lanes[found], h.prim[found], h.t[found]
            points = origins[:, lanes] + d[:, lanes] * t
            # emitter_accel's primitives are the emitting triangles in order: their area-light entities.
            total[lanes] += lights.pdf_li(prim, origins[:, lanes], points, selection, measure)
            tmin[lanes] = t * np.float32(1 + 1e-5)
        return total

    result = chi2_test_directions(sample, pdf, sample_count=300_000, res_z=80, res_phi=160, seed=7, dims=3,
                                  test_count=4)
    assert result.passed, str(result)
