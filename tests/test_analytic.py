"""Scenes with answers known in closed form or by independent quadrature."""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace.bsdfs import Conductor, Phong
from pathspace.validate import compare_estimates, furnace_radiance
from pathspace.validate.bsdf import BSDFCheck, bsdf_albedo


def mean_and_error(result, channel=0):
    values = result.image[..., channel]
    return values.mean(), np.sqrt(result.variance[..., channel].sum()) / values.size


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
