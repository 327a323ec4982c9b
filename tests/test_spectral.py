"""Spectral rendering: uplifting, wavelength sampling, XYZ conventions, RGB/spectral agreement, dispersion."""
from __future__ import annotations

import tomllib

import numpy as np
import pytest
from scipy import stats

import pathspace as ps
from pathspace import spectra
from pathspace.bsdfs import Dielectric, Surface
from pathspace.spectra import Cauchy, ColourTable, SpectralColours
from pathspace.validate import compare_estimates, sidak_significance
from conftest import ROOT

D65_WHITE_XY = (0.3127, 0.3290)


def srgb_of_reflectance(spectra_table: np.ndarray) -> np.ndarray:
    """sRGB of reflectance spectra seen under D65 (normalised to Y = 1)."""
    d65 = spectra.Illuminant("D65").on_grid()
    return (spectra.xyz_to_srgb_matrix() @ spectra.spectrum_to_xyz(spectra_table * d65).T).T


def test_uplifted_reflectances_are_bounded_and_round_trip():
    """Mallett-Yuksel uplifting: spectra in [0, 1] at every wavelength; back to the same sRGB within 2e-3."""
    rgb = np.random.default_rng(0).random((2000, 3))
    rgb[:8] = [[0, 0, 0], [1, 1, 1], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [0, 1, 1], [1, 0, 1]]
    table = ColourTable([tuple(c) for c in rgb], "reflectance")
    assert table.spectra.min() >= 0.0 and table.spectra.max() <= 1.0
    assert np.abs(srgb_of_reflectance(table.spectra) - rgb).max() < 2e-3


def test_rgb_emission_round_trips_through_d65():
    """RGB emission becomes uplift(rgb) x D65 / Y(D65): its sRGB is the RGB again; white is D65 with Y = 1."""
    rgb = np.array([[18.387, 13.9873, 6.75357], [1, 1, 1], [0.2, 3.0, 0.7]])
    table = ColourTable([tuple(c) for c in rgb], "illuminant")
    back = (spectra.xyz_to_srgb_matrix() @ spectra.spectrum_to_xyz(table.spectra).T).T
    assert np.all(np.abs(back - rgb) <= 2e-3 * rgb.max(axis=1, keepdims=True))
    xyz_white = spectra.spectrum_to_xyz(table.spectra[1])
    assert abs(xyz_white[1] - 1.0) < 1e-3
    np.testing.assert_allclose(xyz_white[:2] / xyz_white.sum(), D65_WHITE_XY, atol=2e-4)


def test_xyz_normalisation_and_named_spectra():
    """A constant spectral radiance of 1 has Y = 1; illuminants and blackbodies are scaled to Y = scale."""
    assert spectra.spectrum_to_xyz(np.ones(spectra.GRID.size))[1] == pytest.approx(1.0)
    for spectrum in (spectra.Illuminant("A", scale=3.0), spectra.Blackbody(2700.0, scale=3.0)):
        assert spectra.spectrum_to_xyz(spectrum.on_grid())[1] == pytest.approx(3.0)
    # Planck at 6504 K is close to D65 in chromaticity.
    xyz = spectra.spectrum_to_xyz(spectra.Blackbody(6504.0).on_grid())
    assert np.hypot(*(xyz[:2] / xyz.sum() - D65_WHITE_XY)) < 0.01
    with pytest.raises(ValueError, match="unknown name 'D66'"):
        spectra.Illuminant("D66").on_grid()


@pytest.mark.parametrize("method", spectra.WAVELENGTH_SAMPLING)
def test_wavelength_sampling_chi2(method):
    """Each of the four wavelengths of a path is distributed with the claimed density (chi-square over 60 bins)."""
    lam, pdf = spectra.sample_wavelengths(np.random.default_rng(1).random(200_000), method)
    np.testing.assert_allclose(pdf, spectra.wavelength_pdf(lam, method))
    edges = np.linspace(spectra.LAMBDA_MIN, spectra.LAMBDA_MAX, 61)
    fine = np.linspace(spectra.LAMBDA_MIN, spectra.LAMBDA_MAX, 60 * 200 + 1)
    density = spectra.wavelength_pdf(fine, method)
    expected = np.array([np.trapezoid(density[k * 200:(k + 1) * 200 + 1], fine[k * 200:(k + 1) * 200 + 1])
                         for k in range(60)])
    assert abs(expected.sum() - 1.0) < 1e-6
    for row in lam:
        observed = np.histogram(row, edges)[0]
        p = stats.chisquare(observed, expected * row.size).pvalue
        assert p > sidak_significance(0.01, 8), (method, p)
    # The four wavelengths of a path are the hero's sample rotated by quarters.
    u = (lam[0] - spectra.LAMBDA_MIN) / (spectra.LAMBDA_MAX - spectra.LAMBDA_MIN)
    if method == "uniform":
        np.testing.assert_allclose((u + 0.25) % 1.0, (lam[1] - 360) / 470, atol=1e-9)


def test_radiance_to_xyz_is_unbiased():
    """A constant spectral radiance of 1, estimated from sampled wavelengths, averages to XYZ of 1."""
    lam, pdf = spectra.sample_wavelengths(np.random.default_rng(2).random(400_000), "visible")
    index, frac = spectra.grid_position(lam)
    xyz = spectra.radiance_to_xyz(np.ones_like(lam), index, frac, pdf)
    exact = spectra.spectrum_to_xyz(np.ones(spectra.GRID.size))
    assert np.all(np.abs(xyz.mean(axis=1) - exact) < 4 * xyz.std(axis=1) / np.sqrt(lam.shape[1]) + 1e-4)


def flat_cornell(resolution=(48, 48), specular=False):
    """The Cornell box (or its specular variant) with grey materials and an equal-energy light."""
    name = "cornell-box-specular" if specular else "cornell-box"
    data = tomllib.loads((ROOT / "scenes" / name / "scene.toml").read_text())
    data["camera"]["resolution"] = list(resolution)
    for material in data["materials"].values():
        if material["type"] == "diffuse":
            material["reflectance"] = [0.6] * 3
    data["shapes"][0]["emitter"] = {"radiance": {"illuminant": "E", "scale": 15.0}}
    return ps.scene_from_dict(data)


@pytest.mark.parametrize("specular", [False, True], ids=["diffuse", "glass-and-mirror"])
def test_flat_scene_is_the_same_in_rgb_and_spectral(specular):
    """Constant reflectances and an equal-energy light: RGB and spectral renders estimate the same image
    (with non-dispersive glass too)."""
    scene = flat_cornell(specular=specular)
    assert scene.spectral_reasons() == ["an area light emits a spectrum"]
    spp = 256 if specular else 128
    rgb = ps.render(scene, spp=spp, seed=1, spectral=False)
    spectral = ps.render(scene, spp=spp, seed=2)
    assert spectral.stats["mode"] == "spectral" and rgb.stats["mode"] == "rgb"
    result = compare_estimates(rgb.image, rgb.variance, spectral.image, spectral.variance, block=8, alpha=1e-3)
    assert result.passed, str(result)


def test_white_patch_under_d65_is_neutral():
    """A white diffuse plane lit by a D65 area light: sRGB chromaticity within 1e-3 of the D65 white point."""
    scene = ps.scene_from_dict({
        "camera": {"position": [0, 1, 2], "look_at": [0, 0, 0], "fov": 30, "resolution": [32, 32]},
        "materials": {"white": {"type": "diffuse", "reflectance": [1, 1, 1]},
                      "black": {"type": "diffuse", "reflectance": [0, 0, 0]}},
        "shapes": [{"type": "quad", "corner": [-3, 0, 3], "edge_u": [6, 0, 0], "edge_v": [0, 0, -6],
                    "material": "white"},
                   {"type": "quad", "corner": [-1, 2, -1], "edge_u": [2, 0, 0], "edge_v": [0, 0, 2],
                    "material": "black", "emitter": {"radiance": {"illuminant": "D65"}}}],
    })
    result = ps.render(scene, spp=64, seed=3)
    xyz = result.xyz.reshape(-1, 3).mean(axis=0)
    assert np.hypot(*(xyz[:2] / xyz.sum() - D65_WHITE_XY)) < 1e-3
    rgb = result.image.reshape(-1, 3).mean(axis=0)
    assert np.abs(rgb / rgb.mean() - 1.0).max() < 5e-3


def test_dispersion_separates_wavelengths_in_order():
    """Through a prism (two refractions of a Cauchy glass), shorter wavelengths are deviated more."""
    glass = Dielectric(Cauchy(1.6, 0.01))
    wavelengths = np.linspace(400, 700, 16)
    # Enter one face of a 60-degree prism at 55 degrees from its normal, leave through the other face.
    n1 = np.array([0.0, 0.0, 1.0])
    n2 = np.array([np.sin(np.radians(60)), 0.0, -np.cos(np.radians(60))])  # outward normal of the exit face
    incoming = np.array([np.sin(np.radians(55)), 0.0, -np.cos(np.radians(55))])
    exits = []
    for lam in wavelengths:
        colours = SpectralColours(np.full((4, 1), lam), *spectra.grid_position(np.full((4, 1), lam)))
        params = Dielectric.gather(Dielectric.tables([glass]), np.zeros(1, dtype=np.int64), colours, {})
        inside = Dielectric.sample(params, Surface.facing(n1[:, None].astype(np.float32),
                                                          incoming[:, None].astype(np.float32)),
                                   np.full((3, 1), 0.9999)).wi
        out = Dielectric.sample(params, Surface.facing(n2[:, None].astype(np.float32), inside),
                                np.full((3, 1), 0.9999))
        assert out.weight[0, 0] > 0 and np.all(out.weight[1:, 0] == 0) and out.terminated[0]  # secondaries terminated
        assert n2 @ out.wi[:, 0] > 0  # refracted out of the prism (no total internal reflection)
        exits.append(np.degrees(np.arccos(np.clip(incoming @ out.wi[:, 0].astype(np.float64), -1, 1))))
    deviation = np.array(exits)
    assert np.all(np.diff(deviation) < 0)      # blue (400 nm) deviated most, red least
    assert deviation[0] - deviation[-1] > 1.0  # by more than a degree for this flint glass


@pytest.mark.parametrize("ior", [1.5, {"cauchy": [1.5, 0.0]}, {"cauchy": [1.5046, 0.0042]}],
                         ids=["constant", "cauchy-flat", "cauchy-bk7"])
def test_glass_slab_before_a_white_environment_shows_white(ior):
    """Every path through a glass slab ends in the environment with weight 1 (the 1/eta^2 of entering
    and leaving cancel), so the image is the environment's white, 1, dispersive or not -- also after
    two dispersive interfaces, where terminating the secondary wavelengths twice would give 4."""
    scene = ps.scene_from_dict({
        "camera": {"position": [0, 0, 5], "look_at": [0, 0, 0], "fov": 10, "resolution": [8, 8]},
        "materials": {"glass": {"type": "dielectric", "ior": ior}},
        "shapes": [{"type": "box", "center": [0, 0, 0], "size": [4, 4, 1], "material": "glass"}],
        "lights": [{"type": "environment", "radiance": [1, 1, 1]}]})
    result = ps.render(scene, spp=512, seed=1, spectral=True)
    mean = result.image.mean(axis=(0, 1))
    error = np.sqrt(result.variance.sum(axis=(0, 1))) / (8 * 8)
    assert np.all(np.abs(mean - 1.0) < 4 * error) and np.all(error < 0.02), (mean, error)


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
    data = tomllib.loads((ROOT / "scenes" / "cornell-box-measured" / "scene.toml").read_text())
    data["camera"]["resolution"] = [32, 32]
    scene = ps.scene_from_dict(data)
    result = ps.render(scene, spp=8, seed=5)
    assert result.stats["mode"] == "spectral" and "spectral data" in result.stats["mode_reason"]
    assert result.stats["params"]["max_depth"] == -1 and np.all(np.isfinite(result.image))
    # The red wall is on the left of the image, the green on the right.
    left, right = result.image[16, 2], result.image[16, -4]
    assert left[0] > 5 * left[1] and right[1] > 1.5 * right[0]
    forced = ps.render(scene, spp=2, seed=5, spectral=False)
    assert forced.stats["mode"] == "rgb" and "reduced to RGB" in forced.stats["mode_reason"]


@pytest.mark.parametrize("spectrum, message", [
    ({"wavelengths": [400, 500], "values": [1]}, "same length"),
    ({"wavelengths": [500, 400], "values": [1, 1]}, "increasing"),
    ({"wavelengths": [400, 500], "values": [1, -1]}, ">= 0"),
    ({"wavelengths": [400, 500], "values": [0.5, 1.5]}, "reflectance spectrum must not exceed 1"),
    ({"illuminant": "D66"}, "unknown name 'D66'"),
    ({"blackbody": -5}, "expected a number > 0"),
    ({"file": "nothere.csv"}, "spectrum file not found"),
    ({"blackbody": 3000, "illuminant": "A"}, "exactly one of"),
])
def test_spectrum_errors(spectrum, message, tmp_path):
    data = {"camera": {"position": [0, 0, 5], "look_at": [0, 0, 0], "fov": 40, "resolution": [4, 4]},
            "materials": {"m": {"type": "diffuse", "reflectance": spectrum}},
            "shapes": [{"type": "quad", "corner": [0, 0, 0], "edge_u": [1, 0, 0], "edge_v": [0, 1, 0],
                        "material": "m"}]}
    with pytest.raises(ps.SceneError, match=r"materials.m.reflectance.*" + message):
        ps.scene_from_dict(data, source="s.toml", base_dir=tmp_path)


def test_spectrum_from_csv(tmp_path):
    (tmp_path / "r.csv").write_text("wavelength,value\n400,0.2\n550,0.4\n700,0.6\n")
    data = {"camera": {"position": [0, 0, 5], "look_at": [0, 0, 0], "fov": 40, "resolution": [4, 4]},
            "materials": {"m": {"type": "diffuse", "reflectance": {"file": "r.csv", "scale": 0.5}}},
            "shapes": [{"type": "quad", "corner": [0, 0, 0], "edge_u": [1, 0, 0], "edge_v": [0, 1, 0],
                        "material": "m"}]}
    scene = ps.scene_from_dict(data, base_dir=tmp_path)
    table = scene.materials.tables[0]["reflectance"]
    np.testing.assert_allclose(table.spectra[0, [40, 190, 340]], [0.1, 0.2, 0.3])  # 400, 550, 700 nm
    assert table.spectra[0, 0] == 0.0  # zero outside the given wavelengths
