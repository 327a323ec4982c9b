"""Checks of scattering models: chi-square of sampling, sample/eval/pdf consistency, energy conservation.

All checks take a model instance (e.g. ``Conductor(eta, k, alpha)``), an
outgoing direction ``wo`` and a normal, and run the model's vectorised
functions on many lanes at once.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..bsdfs import MaterialTable, Surface
from ..spectra import RGBColours
from .chi2 import ChiSquareResult, chi2_test_directions

__all__ = ["BSDFCheck", "bsdf_chi2", "bsdf_consistency", "bsdf_albedo", "fresnel_dielectric_albedo"]


class BSDFCheck:
    """A material evaluated at a fixed (wo, n) on any number of lanes."""

    def __init__(self, material, wo, normal=(0.0, 0.0, 1.0), options: dict | None = None, mode: str = "radiance"):
        self.material = material
        self.table = MaterialTable(["m"], [material])
        self.model = self.table.kinds[0]
        self.wo = np.asarray(wo, dtype=np.float64) / np.linalg.norm(wo)
        self.normal = np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)
        self.options = options or {}
        self.mode = mode

    def _lanes(self, count: int):
        ids = np.zeros(count, dtype=np.int64)
        params = self.table.gather(0, ids, RGBColours, self.options)
        n = np.repeat(self.normal.astype(np.float32)[:, None], count, axis=1)
        wo = np.repeat(self.wo.astype(np.float32)[:, None], count, axis=1)
        return params, Surface.facing(n, -wo)

    def sample(self, u: np.ndarray):
        """The model's samples for uniforms u (3, N)."""
        params, surface = self._lanes(u.shape[1])
        return self.model.sample(params, surface, u, self.mode)

    def eval(self, wi: np.ndarray):
        """(f |cos|, pdf) at directions wi (3, N)."""
        params, surface = self._lanes(wi.shape[1])
        return self.model.eval(params, surface, wi.astype(np.float32))


def bsdf_chi2(check: BSDFCheck, *, sample_count: int = 500_000, seed: int = 0, test_count: int = 1,
              res_z: int | None = None, res_phi: int | None = None) -> ChiSquareResult:
    """Chi-square test of the model's sampled directions against its own pdf (non-delta models)."""
    def sample(u):
        s = check.sample(u)
        return s.wi, (s.pdf > 0) & np.any(s.weight > 0, axis=0)

    def pdf(directions):
        return check.eval(directions)[1]

    return chi2_test_directions(sample, pdf, sample_count=sample_count, seed=seed, test_count=test_count, dims=3,
                                res_z=res_z, res_phi=res_phi)


@dataclass
class ConsistencyResult:
    """Largest relative disagreements found by :func:`bsdf_consistency`."""

    pdf_error: float      # |pdf(sample) - eval pdf| / pdf
    weight_error: float   # |weight - f cos / pdf| / max(weight)
    samples: int

    def ok(self, tolerance: float = 1e-4) -> bool:
        return self.pdf_error <= tolerance and self.weight_error <= tolerance


def bsdf_consistency(check: BSDFCheck, *, sample_count: int = 100_000, seed: int = 0) -> ConsistencyResult:
    """Compare, for every non-delta sample, its pdf with ``eval``'s pdf and its weight with f cos / pdf.

    Samples at grazing angles (cos < 1e-3) are left out: float32 directions
    make their densities ill-conditioned.
    """
    rng = np.random.default_rng(seed)
    s = check.sample(rng.random((3, sample_count)))
    valid = (s.pdf > 0) & ~s.delta & np.all(np.isfinite(s.weight), axis=0)
    cos_i = np.abs(check.normal @ s.wi.astype(np.float64))
    valid &= cos_i > 1e-3
    f_cos, pdf = check.eval(s.wi[:, valid])
    sampled_pdf = s.pdf[valid]
    pdf_error = np.max(np.abs(pdf - sampled_pdf) / sampled_pdf, initial=0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        expected = np.where(pdf > 0, f_cos / pdf, 0.0)
    scale = max(float(np.max(np.abs(s.weight[:, valid]), initial=0.0)), 1e-300)
    weight_error = np.max(np.abs(expected - s.weight[:, valid]), initial=0.0) / scale
    return ConsistencyResult(float(pdf_error), float(weight_error), int(valid.sum()))


def bsdf_albedo(check: BSDFCheck, *, sample_count: int = 200_000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Directional albedo per channel, the integral of f cos over wi, estimated as the mean sample weight.

    Returns (albedo (C,), standard error (C,)).
    """
    rng = np.random.default_rng(seed)
    weight = check.sample(rng.random((3, sample_count))).weight
    return weight.mean(axis=1), weight.std(axis=1) / np.sqrt(sample_count)


def fresnel_dielectric_albedo(cos_i: float, eta: float) -> float:
    """Fresnel reflectance of a smooth dielectric at incidence cos_i and relative index eta (a reference value)."""
    from ..bsdfs.fresnel import fresnel_dielectric

    return float(fresnel_dielectric(np.array([cos_i]), np.array([eta]))[0][0])
