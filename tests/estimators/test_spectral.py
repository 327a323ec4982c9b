"""Spectral rendering through the estimators: RGB and spectral renders of a flat-spectrum scene agree
(path tracing with and without glass and mirror, BDPT); glass slabs before a white sky show white,
dispersive or not; the prism scene spreads the spectrum in order; the measured Cornell box renders
spectrally (and reduced to RGB on request).  (Estimators agreeing with each other on spectral scenes --
the measured Cornell box, dispersive glass -- are in the agreement matrix, test_agreement.py.)"""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from conftest import ROOT, agree, scene_dict


def flat_cornell(resolution=(48, 48), specular=False):
    """The Cornell box (or its specular variant) with grey materials and an equal-energy light."""
    data = scene_dict("cornell-box-specular" if specular else "cornell-box", resolution)
    for material in data["materials"].values():
        if material["type"] == "diffuse":
            material["reflectance"] = [0.6] * 3
    data["shapes"][0]["emitter"] = {"radiance": {"illuminant": "E", "scale": 15.0}}
    return ps.scene_from_dict(data)


@pytest.mark.parametrize("estimator, specular, resolution, spp", [
    ("pt", False, (48, 48), 128), ("pt", True, (48, 48), 256), ("bdpt", False, (16, 16), 128)],
    ids=["pt-diffuse", "pt-glass-and-mirror", "bdpt-diffuse"])
def test_flat_scene_is_the_same_in_rgb_and_spectral(estimator, specular, resolution, spp):
    """Constant reflectances and an equal-energy light: RGB and spectral renders estimate the same image
    (with non-dispersive glass too)."""
    scene = flat_cornell(resolution, specular)
    assert scene.spectral_reasons() == ["an area light emits a spectrum"]
    rgb = ps.render(scene, estimator, spp=spp, seed=1, spectral=False)
    spectral = ps.render(scene, estimator, spp=spp, seed=2)
    assert spectral.stats["mode"] == "spectral" and rgb.stats["mode"] == "rgb"
    ok, report = agree(rgb, spectral)
    assert ok, report


@pytest.mark.parametrize("estimator, ior, spp, seed, precision", [
    ("pt", 1.5, 512, 1, 0.02), ("pt", {"cauchy": [1.5, 0.0]}, 512, 1, 0.02),
    ("pt", {"cauchy": [1.5046, 0.0042]}, 512, 1, 0.02), ("bdpt", {"cauchy": [1.5046, 0.0042]}, 256, 3, 0.03)],
    ids=["pt-constant", "pt-cauchy-flat", "pt-cauchy-bk7", "bdpt-cauchy-bk7"])
def test_glass_slab_before_a_white_environment_shows_white(estimator, ior, spp, seed, precision):
    """Every path through a glass slab ends in the environment with weight 1 (the 1/eta^2 of entering
    and leaving cancel), so the image is the environment's white, 1, dispersive or not -- also after
    two dispersive interfaces, where terminating the secondary wavelengths twice would give 4."""
    scene = ps.scene_from_dict({
        "camera": {"position": [0, 0, 5], "look_at": [0, 0, 0], "fov": 10, "resolution": [8, 8]},
        "materials": {"glass": {"type": "dielectric", "ior": ior}},
        "shapes": [{"type": "box", "center": [0, 0, 0], "size": [4, 4, 1], "material": "glass"}],
        "lights": [{"type": "environment", "radiance": [1, 1, 1]}]})
    result = ps.render(scene, estimator, spp=spp, seed=seed, spectral=True)
    mean = result.image.mean(axis=(0, 1))
    error = np.sqrt(result.variance.sum(axis=(0, 1))) / (8 * 8)
    assert np.all(np.abs(mean - 1.0) < 4 * error) and np.all(error < precision), (mean, error)


def test_prism_scene_spreads_the_spectrum_in_order():
    """The prism scene's image of the white strip: violet to the left of red, as the refraction predicts."""
    result = ps.render(ps.load_scene(ROOT / "scenes" / "prism" / "scene.toml"), spp=32, seed=4)
    assert result.stats["mode"] == "spectral" and "dispersive" in result.stats["mode_reason"]
    xyz = result.xyz.sum(axis=0)  # (width, 3): column profiles of the strip
    columns = np.arange(xyz.shape[0])
    centroid = lambda weight: float((columns * weight).sum() / weight.sum())
    blue_heavy = np.maximum(xyz[:, 2] - xyz[:, 0], 0)  # Z beyond X: short wavelengths
    red_heavy = np.maximum(xyz[:, 0] - xyz[:, 2], 0)
    assert centroid(red_heavy) - centroid(blue_heavy) > 4.0
    assert result.stats["nonfinite"] == 0


def test_measured_cornell_box_renders_spectrally():
    scene = ps.scene_from_dict(scene_dict("cornell-box-measured", (32, 32)))
    result = ps.render(scene, spp=8, seed=5)
    assert result.stats["mode"] == "spectral" and "spectral data" in result.stats["mode_reason"]
    assert result.stats["params"]["max_depth"] == -1 and np.all(np.isfinite(result.image))
    # The red wall is on the left of the image, the green on the right.
    left, right = result.image[16, 2], result.image[16, -4]
    assert left[0] > 5 * left[1] and right[1] > 1.5 * right[0]
    forced = ps.render(scene, spp=2, seed=5, spectral=False)
    assert forced.stats["mode"] == "rgb" and "reduced to RGB" in forced.stats["mode_reason"]

