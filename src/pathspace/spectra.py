"""Spectra, colour tables and wavelength sampling; colour-science owns the colour science.

Conventions (those of pbrt-v4 and Mitsuba 3, so that images are comparable):

* Wavelengths span the visible range [360, 830] nm.  Spectra are tabulated on
  a 1 nm grid over it and linearly interpolated.
* CIE XYZ uses the CIE 1931 2-degree observer, normalised so that a constant
  spectral radiance of 1 has Y = 1:  X = int L(l) x(l) dl / int y(l) dl, etc.
* XYZ to linear sRGB is colour-science's sRGB matrix (D65 white, no chromatic
  adaptation).
* RGB reflectances become spectra by Mallett & Yuksel's spectral primary
  decomposition ("Spectral Primary Decomposition for Rendering with sRGB
  Reflectance", EGSR 2019; colour-science's basis): rho(l) = r B_r(l) +
  g B_g(l) + b B_b(l).  The basis is bounded and sums to one, so any RGB in
  [0, 1]^3 gives a smooth reflectance in [0, 1] at every wavelength, and the
  map is linear: no lookup table is needed.  (Jakob & Hanika 2019 gives
  smoother spectra but needs a table that takes minutes to build.)  RGB
  values that are not reflectances (indices of refraction) use the same map,
  unbounded.
* RGB emission becomes the uplifted spectrum times the D65 illuminant,
  normalised to Y = 1: an emitter of RGB (1, 1, 1) emits D65 with luminance 1,
  and any RGB emission comes back as itself in sRGB.
* Sampled spectra are zero outside the wavelengths they are given at.

Everything here is computed on first use, never at import.
"""
from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from functools import lru_cache
from typing import Union

import numpy as np

__all__ = [
    "LAMBDA_MIN", "LAMBDA_MAX", "GRID", "SampledSpectrum", "Blackbody", "Illuminant", "Colour", "ColourTable",
    "Cauchy", "Sellmeier", "check_colour", "check_emission", "mean_rgb", "is_spectral", "cmfs", "xyz_to_srgb_matrix", "spectrum_to_xyz", "sample_wavelengths",
    "WAVELENGTH_SAMPLING", "WAVELENGTHS_PER_PATH", "SpectralColours", "RGBColours", "RGBMode", "SpectralMode",
    "radiance_to_xyz", "grid_position", "wavelength_pdf", "colour_mode",
]

LAMBDA_MIN, LAMBDA_MAX = 360.0, 830.0
GRID = np.arange(LAMBDA_MIN, LAMBDA_MAX + 0.5, 1.0)
WAVELENGTHS_PER_PATH = 4
WAVELENGTH_SAMPLING = ("uniform", "visible")
KINDS = ("reflectance", "unbounded", "illuminant")


# -- colour-science data, on the grid --------------------------------------------------------------

@lru_cache(maxsize=None)
def _colour():
    from ._colour import colour

    return colour


@lru_cache(maxsize=None)
def cmfs() -> np.ndarray:
    """CIE 1931 2-degree colour matching functions on :data:`GRID`, (3, G)."""
    colour = _colour()
    data = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    return np.stack([np.interp(GRID, data.wavelengths, data.values[:, c]) for c in range(3)])


@lru_cache(maxsize=None)
def _y_integral() -> float:
    return float(np.trapezoid(cmfs()[1], GRID))


@lru_cache(maxsize=None)
def _named_illuminant(name: str) -> np.ndarray:
    colour = _colour()
    if name not in colour.SDS_ILLUMINANTS:
        raise ValueError(f"illuminant: unknown name {name!r} (colour-science knows e.g. "
                         f"{', '.join(list(colour.SDS_ILLUMINANTS)[:12])}, ...)")
    sd = colour.SDS_ILLUMINANTS[name]
    return np.interp(GRID, sd.wavelengths, sd.values, left=0.0, right=0.0)


@lru_cache(maxsize=None)
def _d65_normalised() -> np.ndarray:
    """D65 on the grid, scaled to Y = 1."""
    d65 = _named_illuminant("D65")
    return d65 / spectrum_to_xyz(d65)[1]


@lru_cache(maxsize=None)
def _mallett_basis() -> np.ndarray:
    """Mallett & Yuksel's sRGB basis spectra on the grid, (3, G) (constant beyond their 380-780 nm)."""
    basis = _colour().recovery.MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019
    return np.stack([np.interp(GRID, basis.wavelengths, basis.values[:, c]) for c in range(3)])


@lru_cache(maxsize=None)
def xyz_to_srgb_matrix() -> np.ndarray:
    """colour-science's XYZ -> linear sRGB matrix (D65, no chromatic adaptation)."""
    return np.asarray(_colour().RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB, dtype=np.float64)


def spectrum_to_xyz(values: np.ndarray) -> np.ndarray:
    """XYZ of spectra tabulated on the grid ((G,) or (M, G)), normalised so that 1 everywhere has Y = 1."""
    return np.trapezoid(np.asarray(values)[..., None, :] * cmfs(), GRID, axis=-1) / _y_integral()


# -- scene-level spectra ---------------------------------------------------------------------------

@dataclass(frozen=True)
class SampledSpectrum:
    """A spectrum given at wavelengths (nm, increasing), linear in between, zero outside; times ``scale``."""

    wavelengths: tuple[float, ...]
    values: tuple[float, ...]
    scale: float = 1.0

    def __post_init__(self) -> None:
        w = np.asarray(self.wavelengths, dtype=np.float64)
        v = np.asarray(self.values, dtype=np.float64)
        if w.ndim != 1 or w.shape != v.shape or w.size < 2:
            raise ValueError("spectrum: expected wavelengths and values of the same length (at least 2)")
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(v)) and np.all(np.diff(w) > 0)):
            raise ValueError("spectrum: wavelengths must be finite and increasing, values finite")
        if np.any(v < 0) or not (np.isfinite(self.scale) and self.scale >= 0):
            raise ValueError("spectrum: values and scale must be >= 0")

    @classmethod
    def from_csv(cls, path: str | os.PathLike, scale: float = 1.0) -> "SampledSpectrum":
        """Read two columns (wavelength in nm, value) from a CSV file; lines that are not numbers are skipped."""
        rows = []
        with open(path, newline="", encoding="utf-8") as handle:
            for row in csv.reader(handle):
                try:
                    rows.append((float(row[0]), float(row[1])))
                except (ValueError, IndexError):
                    continue
        if len(rows) < 2:
            raise ValueError(f"spectrum: {path} holds fewer than two (wavelength, value) rows")
        w, v = zip(*rows)
        return cls(tuple(w), tuple(v), scale)

    def on_grid(self) -> np.ndarray:
        return self.scale * np.interp(GRID, self.wavelengths, self.values, left=0.0, right=0.0)


@dataclass(frozen=True)
class Blackbody:
    """Planck's law at ``temperature`` kelvin, normalised to luminance Y = ``scale``."""

    temperature: float
    scale: float = 1.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.temperature) and self.temperature > 0):
            raise ValueError(f"blackbody: expected a temperature > 0 K, got {self.temperature!r}")
        if not (np.isfinite(self.scale) and self.scale >= 0):
            raise ValueError("blackbody: scale must be >= 0")

    def on_grid(self) -> np.ndarray:
        colour = _colour()
        sd = colour.sd_blackbody(self.temperature, colour.SpectralShape(LAMBDA_MIN, LAMBDA_MAX, 1.0))
        values = np.interp(GRID, sd.wavelengths, sd.values)
        return self.scale * values / spectrum_to_xyz(values)[1]


@dataclass(frozen=True)
class Illuminant:
    """A CIE illuminant known to colour-science by ``name`` ("D65", "A", "F2", ...), normalised to Y = ``scale``."""

    name: str
    scale: float = 1.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.scale) and self.scale >= 0):
            raise ValueError("illuminant: scale must be >= 0")

    def on_grid(self) -> np.ndarray:
        values = _named_illuminant(self.name)
        return self.scale * values / spectrum_to_xyz(values)[1]


Colour = Union[tuple, SampledSpectrum, Blackbody, Illuminant]


def is_spectral(value: Colour) -> bool:
    """Whether a colour is given as a spectrum rather than RGB."""
    return isinstance(value, (SampledSpectrum, Blackbody, Illuminant))


def check_colour(value: Colour, name: str, kind: str) -> Colour:
    """Validate a colour parameter: an RGB triple (>= 0; <= 1 for reflectances) or a spectrum object."""
    from .checks import triple

    if is_spectral(value):
        if kind == "reflectance" and value.on_grid().max() > 1.0 + 1e-9:
            raise ValueError(f"{name}: a reflectance spectrum must not exceed 1")
        return value
    return tuple(float(x) for x in triple(value, name, low=0.0, high=1.0 if kind == "reflectance" else None))


def check_emission(value: Colour, name: str) -> Colour:
    """Validate an emission colour: RGB >= 0 or a spectrum, not zero everywhere."""
    value = check_colour(value, name, "illuminant")
    positive = value.on_grid().max() > 0 if is_spectral(value) else max(value) > 0
    if not positive:
        raise ValueError(f"{name}: expected at least one positive component")
    return value


def mean_rgb(value: Colour, kind: str = "illuminant") -> float:
    """Mean of the RGB values of a colour (its magnitude, for light selection by power)."""
    return float(ColourTable([value], kind).mean()[0])


class ColourTable:
    """The values of one colour parameter for M materials or lights, in RGB and as spectra.

    ``kind`` says how each representation is derived from the other:
    "reflectance" (bounded albedos), "unbounded" (e.g. indices of
    refraction), "illuminant" (emission); see the module docstring.
    """

    def __init__(self, entries: list[Colour], kind: str) -> None:
        if kind not in KINDS:
            raise ValueError(f"colour kind: expected one of {KINDS}, got {kind!r}")
        self.entries = list(entries)
        self.kind = kind
        self.spectral = any(is_spectral(e) for e in self.entries)
        rgb = np.zeros((3, len(self.entries)))
        for m, entry in enumerate(self.entries):
            rgb[:, m] = self._to_rgb(entry) if is_spectral(entry) else np.asarray(entry, dtype=np.float64)
        self.rgb = rgb

    def __len__(self) -> int:
        return len(self.entries)

    def _to_rgb(self, entry) -> np.ndarray:
        values = entry.on_grid()
        if self.kind == "illuminant":
            return xyz_to_srgb_matrix() @ spectrum_to_xyz(values)
        # Reflectances and other spectral quantities: their colour under D65, white-normalised.
        rgb = xyz_to_srgb_matrix() @ spectrum_to_xyz(values * _d65_normalised())
        return np.clip(rgb, 0.0, 1.0) if self.kind == "reflectance" else np.maximum(rgb, 0.0)

    @property
    def spectra(self) -> np.ndarray:
        """(M, G) spectra on :data:`GRID` (built on first use)."""
        if not hasattr(self, "_spectra"):
            table = np.zeros((len(self.entries), GRID.size))
            basis = _mallett_basis()
            for m, entry in enumerate(self.entries):
                if is_spectral(entry):
                    table[m] = entry.on_grid()
                else:
                    table[m] = np.asarray(entry, dtype=np.float64) @ basis
                    if self.kind == "illuminant":
                        table[m] *= _d65_normalised()
            if self.kind == "reflectance":
                np.clip(table, 0.0, 1.0, out=table)  # the basis sums to 1 up to rounding
            self._spectra = table
        return self._spectra

    def mean(self) -> np.ndarray:
        """Average over channels (RGB) of each entry, (M,): a colour-blind magnitude for light selection."""
        return self.rgb.mean(axis=0)


# -- dispersion -------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Cauchy:
    """Cauchy's equation n(l) = a + b / l^2, with l in micrometres (e.g. BK7: a = 1.5046, b = 0.00420)."""

    a: float
    b: float

    def __post_init__(self) -> None:
        if not (np.isfinite(self.a) and np.isfinite(self.b) and self.a > 0):
            raise ValueError(f"cauchy: expected a > 0 and finite b, got {self.a!r}, {self.b!r}")
        if np.any(self(GRID) <= 0):
            raise ValueError(f"cauchy: a = {self.a!r}, b = {self.b!r} give an index <= 0 within 360-830 nm")

    def __call__(self, wavelength_nm: np.ndarray) -> np.ndarray:
        um = np.asarray(wavelength_nm, dtype=np.float64) * 1e-3
        return self.a + self.b / (um * um)


@dataclass(frozen=True)
class Sellmeier:
    """Sellmeier's equation n^2 = 1 + sum B_i l^2 / (l^2 - C_i), l in micrometres (e.g. BK7:
    B = 1.03961212, 0.231792344, 1.01046945; C = 0.00600069867, 0.0200179144, 103.560653)."""

    b: tuple[float, float, float]
    c: tuple[float, float, float]

    def __post_init__(self) -> None:
        if len(self.b) != 3 or len(self.c) != 3 or not np.all(np.isfinite(self.b + self.c)):
            raise ValueError("sellmeier: expected three finite B and three finite C coefficients")
        if np.any(self(GRID) <= 0) or not np.all(np.isfinite(self(GRID))):
            raise ValueError("sellmeier: the coefficients give no real index over 360-830 nm")

    def __call__(self, wavelength_nm: np.ndarray) -> np.ndarray:
        l2 = (np.asarray(wavelength_nm, dtype=np.float64) * 1e-3) ** 2
        n2 = 1.0 + sum(bi * l2 / (l2 - ci) for bi, ci in zip(self.b, self.c))
        with np.errstate(invalid="ignore"):
            return np.sqrt(n2)


# -- wavelength sampling ----------------------------------------------------------------------------

# pbrt-v4's density for "visible" sampling, p(l) ~ 1 / cosh^2(B (l - C)), here normalised over [360, 830].
_VISIBLE_B, _VISIBLE_C = 0.0072, 538.0


def _visible_bounds() -> tuple[float, float]:
    return np.tanh(_VISIBLE_B * (LAMBDA_MIN - _VISIBLE_C)), np.tanh(_VISIBLE_B * (LAMBDA_MAX - _VISIBLE_C))


def wavelength_pdf(wavelengths: np.ndarray, method: str) -> np.ndarray:
    """Density (per nm) of one wavelength under ``method``."""
    if method == "uniform":
        return np.full(np.shape(wavelengths), 1.0 / (LAMBDA_MAX - LAMBDA_MIN))
    lo, hi = _visible_bounds()
    return _VISIBLE_B / (hi - lo) / np.cosh(_VISIBLE_B * (np.asarray(wavelengths) - _VISIBLE_C)) ** 2


def sample_wavelengths(u: np.ndarray, method: str = "uniform") -> tuple[np.ndarray, np.ndarray]:
    """Hero wavelength sampling: (wavelengths (4, N) nm, pdf (4, N) per nm) from uniforms u (N,).

    The hero wavelength comes from u; the others are the same sample rotated
    by quarters of the unit interval (Wilkie et al. 2014; pbrt-v4's
    SampledWavelengths), so the four cover the spectrum evenly and each is
    marginally distributed with the same density.
    """
    if method not in WAVELENGTH_SAMPLING:
        raise ValueError(f"wavelength sampling: expected one of {WAVELENGTH_SAMPLING}, got {method!r}")
    rotated = (np.asarray(u, dtype=np.float64)[None, :] + np.arange(WAVELENGTHS_PER_PATH)[:, None]
               / WAVELENGTHS_PER_PATH) % 1.0
    if method == "uniform":
        lam = LAMBDA_MIN + rotated * (LAMBDA_MAX - LAMBDA_MIN)
    else:
        lo, hi = _visible_bounds()
        lam = _VISIBLE_C + np.arctanh(lo + rotated * (hi - lo)) / _VISIBLE_B
    lam = np.clip(lam, LAMBDA_MIN, LAMBDA_MAX)
    return lam, wavelength_pdf(lam, method)


def grid_position(wavelengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where wavelengths fall on :data:`GRID`: (index of the sample below, int32; fraction to the next, float64)."""
    position = np.clip(np.asarray(wavelengths, dtype=np.float64) - LAMBDA_MIN, 0.0, GRID.size - 1.0)
    index = np.minimum(position.astype(np.int32), GRID.size - 2)
    return index, position - index


def radiance_to_xyz(radiance: np.ndarray, index: np.ndarray, frac: np.ndarray, pdf: np.ndarray) -> np.ndarray:
    """XYZ (3, N) estimates from radiance at each lane's wavelengths (4, N): mean of L cmf / pdf / int y.

    ``index`` and ``frac`` are the wavelengths' :func:`grid_position`.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        weight = np.where(pdf > 0, radiance / pdf, 0.0) / (WAVELENGTHS_PER_PATH * _y_integral())
    table = cmfs()
    return np.stack([np.sum(weight * (table[c].take(index) * (1 - frac) + table[c].take(index + 1) * frac), axis=0)
                     for c in range(3)])


# -- per-lane colour models ------------------------------------------------------------------------

class RGBColours:
    """RGB rendering: colour parameters are their RGB values (C = 3)."""

    channels = 3
    wavelengths = None

    @staticmethod
    def lookup(table: ColourTable, ids: np.ndarray) -> np.ndarray:
        """Values (3, N) of ``table`` entries ``ids``."""
        return np.take(table.rgb, ids, axis=1)

    @classmethod
    def take(cls, lanes: np.ndarray) -> type["RGBColours"]:
        """The colour model of a subset of the lanes (the same, in RGB)."""
        return cls


class SpectralColours:
    """Spectral rendering: colour parameters evaluated at each lane's 4 wavelengths (C = 4).

    ``index`` and ``frac`` (4, N) are the wavelengths' :func:`grid_position`,
    computed once per path.
    """

    channels = WAVELENGTHS_PER_PATH

    def __init__(self, wavelengths: np.ndarray, index: np.ndarray, frac: np.ndarray) -> None:
        self.wavelengths, self.index, self.frac = wavelengths, index, frac

    def take(self, lanes: np.ndarray) -> "SpectralColours":
        """The colour model of the lanes ``lanes``."""
        return SpectralColours(*(np.take(a, lanes, axis=1) for a in (self.wavelengths, self.index, self.frac)))

    def lookup(self, table: ColourTable, ids: np.ndarray) -> np.ndarray:
        """Values (4, N) of ``table`` entries ``ids`` at the lanes' wavelengths (linear interpolation)."""
        spectra = table.spectra
        flat = spectra.ravel()
        base = np.asarray(ids, dtype=np.int64)[None, :] * spectra.shape[1] + self.index
        low = flat.take(base)
        return low + (flat.take(base + 1) - low) * self.frac


# -- colour modes of a render -----------------------------------------------------------------------

class RGBMode:
    """Render in linear sRGB: three channels, no wavelengths."""

    name = "rgb"
    channels = 3
    camera_dims = 0
    path_fields: tuple[str, ...] = ()
    film_covariance = False
    film_to_srgb = None

    def start(self, u: np.ndarray) -> dict[str, np.ndarray]:
        """Per-path state of new paths (none)."""
        return {}

    def colours(self, paths) -> type[RGBColours]:
        """The colour model of the live paths."""
        return RGBColours

    def to_film(self, radiance: np.ndarray, paths, lanes: np.ndarray) -> np.ndarray:
        """Film values (3, k) of finished paths ``lanes`` with radiance (3, k)."""
        return radiance

    def terminate_secondary(self, paths, lanes: np.ndarray) -> None:
        """Nothing to do: RGB paths carry no wavelengths (dispersion uses one index)."""


class SpectralMode:
    """Render spectrally: each path carries 4 hero-sampled wavelengths; the film accumulates CIE XYZ."""

    name = "spectral"
    channels = WAVELENGTHS_PER_PATH
    camera_dims = 1
    path_fields = ("wavelengths", "wavelength_pdf", "wavelength_index", "wavelength_frac")
    film_covariance = True

    def __init__(self, sampling: str = "uniform") -> None:
        if sampling not in WAVELENGTH_SAMPLING:
            raise ValueError(f"wavelength sampling: expected one of {WAVELENGTH_SAMPLING}, got {sampling!r}")
        self.sampling = sampling

    @property
    def film_to_srgb(self) -> np.ndarray:
        return xyz_to_srgb_matrix()

    def start(self, u: np.ndarray) -> dict[str, np.ndarray]:
        lam, pdf = sample_wavelengths(u[0], self.sampling)
        index, frac = grid_position(lam)
        return {"wavelengths": lam, "wavelength_pdf": pdf, "wavelength_index": index, "wavelength_frac": frac}

    def colours(self, paths) -> SpectralColours:
        return SpectralColours(paths.wavelengths, paths.wavelength_index, paths.wavelength_frac)

    def terminate_secondary(self, paths, lanes: np.ndarray) -> None:
        """Keep only the hero wavelength of the paths where ``lanes`` (N,) bool is set.

        A dispersive interface sent the path along the hero's direction, which
        the other wavelengths would not take.  As in pbrt-v4
        (SampledWavelengths::TerminateSecondary), the secondaries' densities
        become 0 -- they drop out of the film sum -- and the hero's is divided
        by 4, so it stands for all four.  This happens once per path: later
        dispersive interfaces find the secondaries already terminated.
        """
        pdf = paths.wavelength_pdf
        first = lanes & (pdf[1] > 0)
        if first.any():
            pdf[0, first] /= WAVELENGTHS_PER_PATH
            pdf[1:, first] = 0.0

    def to_film(self, radiance: np.ndarray, paths, lanes: np.ndarray) -> np.ndarray:
        return radiance_to_xyz(radiance, *(np.take(a, lanes, axis=1) for a in (
            paths.wavelength_index, paths.wavelength_frac, paths.wavelength_pdf)))


def colour_mode(scene, spectral: bool | None, wavelength_sampling: str = "uniform"):
    """The colour mode of a render of ``scene`` (RGBMode or SpectralMode) and the reason for it:
    ``spectral`` True or False forces it; None renders spectrally when the scene needs it."""
    reasons = scene.spectral_reasons()
    if spectral is None:
        spectral = bool(reasons)
        reason = "; ".join(reasons) if reasons else "every colour in the scene is RGB and nothing disperses"
    else:
        reason = "asked for" + (f" (the scene: {'; '.join(reasons)})" if reasons else "")
        if reasons and not spectral:
            reason += ": spectra are reduced to RGB, dispersion uses the index at 550 nm"
    return (SpectralMode(wavelength_sampling) if spectral else RGBMode()), reason
