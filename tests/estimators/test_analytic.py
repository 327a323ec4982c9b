"""Scenes with answers known in closed form or by independent quadrature: a mirror furnace, a glass sphere
invisible in a white furnace, glossy plates under a constant sky, furnaces with paths of hundreds of
bounces (albedo 0.99), and a furnace to a tenth of a percent.  (Furnaces of albedo 0.5 and 0.9 for every
estimator configuration are in the agreement matrix, test_agreement.py.)"""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace.bsdfs import Conductor, Phong
from pathspace.validate import compare_estimates, furnace_radiance, furnace_scene
from pathspace.validate.bsdf import BSDFCheck, bsdf_albedo
from conftest import mean_and_error, no_nonfinite, scene_dict


def enclosure(material: dict, emission: float, inner_shapes=()) -> ps.Scene:
    return ps.scene_from_dict({
        "camera": {"position": [0.1, 0.05, 0.0], "look_at": [0.3, 0.0, -1.0], "fov": 90.0, "resolution": [24, 24]},
        "materials": {"wall": material, "glass": {"type": "dielectric", "ior": 1.5}},
        "shapes": [{"type": "box", "size": [2, 2, 2], "material": "wall", "flip_normals": True,
                    "emitter": {"radiance": [emission] * 3}}, *inner_shapes],
    })


def test_mirror_furnace():
    """Mirror walls of reflectance R, all emitting Le: L = Le / (1 - R) (paths only end by roulette)."""
    scene = enclosure({"type": "mirror", "reflectance": [0.8, 0.8, 0.8]}, 1.0)
    result = ps.render(scene, spp=64, seed=1)
    mean, error = mean_and_error(result)
    assert error < 0.02 and abs(mean - 5.0) < 3 * error + 1e-9


def test_glass_sphere_in_a_white_furnace_is_invisible():
    """A lossless dielectric in a uniform radiance field changes nothing: L = Le / (1 - rho) everywhere."""
    sphere = {"type": "sphere", "center": [0.3, 0.0, -0.5], "radius": 0.35, "subdivisions": 3, "material": "glass"}
    scene = enclosure({"type": "diffuse", "reflectance": [0.7, 0.7, 0.7]}, 1.0, [sphere])
    exact = furnace_radiance(0.7, 1.0)
    for mode in ("mis", "none"):
        result = ps.render(scene, spp=128, seed=2, light_sampling=mode)
        mean, error = mean_and_error(result)
        assert error < 0.01 * exact and abs(mean - exact) < 3 * error, (mode, mean, error)
        # Block by block too, through the sphere and beside it.
        check = compare_estimates(result.image, result.variance, np.full_like(result.image, exact),
                                  np.zeros_like(result.variance), block=4)
        assert check.passed, (mode, str(check))


@pytest.mark.parametrize("material", [Conductor((1.66, 0.88, 0.52), (9.22, 6.27, 4.84), 0.25),
                                      Phong((0.2, 0.3, 0.1), (0.5, 0.4, 0.6), 30.0)],
                         ids=["aluminium-ggx", "phong"])
def test_glossy_plate_under_a_constant_sky(material):
    """A plate alone under a constant environment L: a pixel sees L * albedo(wo), the plate's directional
    albedo in the viewing direction, computed independently by Monte Carlo integration of the BSDF."""
    if isinstance(material, Conductor):
        spec = {"type": "conductor", "eta": list(material.eta), "k": list(material.k), "alpha": material.alpha}
    else:
        spec = {"type": "phong", "diffuse": list(material.diffuse), "specular": list(material.specular),
                "exponent": material.exponent}
    camera = np.array([0.0, 1.0, 3.0])
    scene = ps.scene_from_dict({
        "camera": {"position": camera.tolist(), "look_at": [0, 0, 0], "fov": 20.0, "resolution": [16, 16]},
        "materials": {"plate": spec},
        "shapes": [{"type": "quad", "corner": [-5, 0, 5], "edge_u": [10, 0, 0], "edge_v": [0, 0, -10],
                    "material": "plate"}],
        "lights": [{"type": "environment", "radiance": [2.0, 2.0, 2.0]}],
    })
    result = ps.render(scene, spp=256, seed=3)
    for px, py in ((8, 8), (3, 12), (13, 4)):
        # The pixel's centre ray hits the plate (y = 0) at:
        origin, direction = scene.camera.generate_rays(np.array([py * 16 + px]), np.full((2, 1), 0.5))
        d = direction[:, 0].astype(np.float64)
        hit = camera + d * (-camera[1] / d[1])
        wo = camera - hit
        albedo, albedo_error = bsdf_albedo(BSDFCheck(material, wo, normal=(0, 1, 0)), sample_count=400_000, seed=px)
        expected = 2.0 * albedo
        value, variance = result.image[py, px], result.variance[py, px]
        # Within the pixel footprint the albedo varies a little; allow 1% for it.
        tolerance = 4 * np.sqrt(variance + (2 * albedo_error) ** 2) + 0.01 * expected
        assert np.all(np.abs(value - expected) < tolerance), (px, py, value, expected, tolerance)



def test_long_path_furnace_path_tracing():
    """Albedo 0.99 (paths of ~100 bounces): L = 100 in every pixel and channel, to 1%."""
    result = ps.render(furnace_scene(0.99), "pt", spp=64, seed=11)
    exact = furnace_radiance(0.99, 1.0)
    mean, error = mean_and_error(result)
    assert error < 0.01 * exact  # the test has the power to see a 3% bias
    assert abs(mean - exact) < 3 * error, (mean, exact, error)
    assert result.stats["nonfinite"] == 0
    # Every channel, not just the first.
    np.testing.assert_allclose(result.image.mean(axis=(0, 1)), exact, rtol=6 * error / exact)


@pytest.mark.slow
def test_long_path_furnace_bdpt():
    """Albedo 0.99: subpaths of more than 200 vertices, every connection finite, L = 100."""
    data = scene_dict("furnace", (8, 8))
    data["materials"]["wall"]["reflectance"] = [0.99] * 3
    result = ps.render(ps.scene_from_dict(data), "bdpt", spp=64, seed=7)
    mean, error = mean_and_error(result)
    assert result.stats["longest_subpath"] > 200 and no_nonfinite(result)
    assert error < 0.02 * 100.0 and abs(mean - 100.0) < 3 * error, (mean, error)


@pytest.mark.slow
def test_furnace_to_a_tenth_of_a_percent():
    for albedo in (0.5, 0.9, 0.99):
        result = ps.render(furnace_scene(albedo, resolution=(64, 64)), spp=256 if albedo < 0.99 else 128, seed=4)
        values = result.image[..., 0]
        error = np.sqrt(result.variance[..., 0].sum()) / values.size
        exact = furnace_radiance(albedo, 1.0)
        assert error < 1e-3 * exact * 1.5
        assert abs(values.mean() - exact) < 3 * error

