"""Area light sampling: selection pmf, consistency of sample() with pdf_sa(), and an unbiased estimate."""
from __future__ import annotations

import numpy as np

import pathspace as ps
from conftest import cornell_dict


def two_light_scene(selection_radiance=(1.0, 8.0)):
    data = cornell_dict((8, 8))
    data["shapes"][0]["emitter"] = {"radiance": [selection_radiance[0]] * 3}
    data["shapes"].append({"name": "lamp2", "type": "quad", "corner": [-0.9, -0.5, -0.99], "edge_u": [0.3, 0, 0],
                           "edge_v": [0, 0.2, 0], "material": "white",
                           "emitter": {"radiance": [selection_radiance[1]] * 3, "two_sided": True}})
    return ps.scene_from_dict(data)


def test_power_pmf_and_sample_pdf_agree_with_pdf_sa():
    scene = two_light_scene()
    lights = scene.lights
    power = lights.area * lights.radiance.mean(axis=0) * np.where(lights.two_sided, 2, 1)
    np.testing.assert_allclose(lights.pmf, power / power.sum())
    rng = np.random.default_rng(0)
    receivers = rng.uniform(-0.8, 0.8, (3, 10_000)).astype(np.float32)
    s = lights.sample(receivers, rng.random((3, 10_000)))
    # Which triangle was sampled: recover it by tracing the sampled direction.
    hits = scene.accel.intersect(receivers, s.wi)
    reached = np.isclose(hits.t, s.distance, rtol=1e-4) & (lights.emitter_of_triangle[hits.prim] >= 0)
    assert reached.sum() > 2000  # unoccluded samples to compare (receivers may sit inside the boxes)
    again = lights.pdf_sa(hits.prim[reached], s.distance[reached], s.cos_light[reached])
    np.testing.assert_allclose(again, s.pdf_sa[reached], rtol=1e-5)


def test_light_sampling_estimates_the_emitted_power_fraction():
    """E[Le |cos_light| ... ] checks: the solid-angle pdf integrates the light's projected solid angle.

    For a receiver point, sum over light samples of 1/pdf_sa estimates the total solid angle the lights
    subtend (one-sided lights only from the front); compare with dense quadrature of the same integral.
    """
    scene = two_light_scene()
    lights = scene.lights
    point = np.array([[0.1], [-0.3], [0.2]], dtype=np.float32)
    rng = np.random.default_rng(1)
    n = 400_000
    s = lights.sample(np.repeat(point, n, axis=1), rng.random((3, n)))
    visible_side = s.radiance[0] > 0
    estimate = np.where(visible_side, 1.0 / s.pdf_sa, 0.0)
    mean, error = estimate.mean(), estimate.std() / np.sqrt(n)
    # Quadrature: solid angle of each emitting triangle seen from the point (front side for one-sided).
    exact = 0.0
    for e, tri in enumerate(lights.triangles):
        p = scene.mesh.vertices[scene.mesh.indices[tri]] - point[:, 0]
        a, b, c = p
        numerator = np.dot(a, np.cross(b, c))
        la, lb, lc = np.linalg.norm(p, axis=1)
        denominator = la * lb * lc + np.dot(a, b) * lc + np.dot(a, c) * lb + np.dot(b, c) * la
        omega = abs(2 * np.arctan2(numerator, denominator))
        facing = np.dot(scene.mesh.normal[:, tri], -p.mean(axis=0)) > 0
        exact += omega if (lights.two_sided[e] or facing) else 0.0
    assert abs(mean - exact) < 4 * error
    assert error < 0.01 * exact


def test_uniform_selection():
    scene = two_light_scene()
    lights = ps.lights.AreaLights(scene.mesh, scene.lights.triangles, scene.lights.radiance, scene.lights.two_sided,
                                  scene.lights.light_of, selection="uniform")
    per_light = np.bincount(lights.light_of, weights=lights.pmf)
    np.testing.assert_allclose(per_light, [0.5, 0.5])
