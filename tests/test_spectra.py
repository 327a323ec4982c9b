"""Spectra and colour: Mallett-Yuksel uplifting (bounded, round-trips), RGB emission through D65, XYZ
normalisation and named spectra, wavelength sampling (chi-square of each method), unbiased XYZ estimates,
a white patch under D65 rendering neutral, and spectra given in scene files (errors, CSV files)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import pathspace as ps
from pathspace import spectra
from pathspace.spectra import ColourTable
from pathspace.validate import sidak_significance


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

