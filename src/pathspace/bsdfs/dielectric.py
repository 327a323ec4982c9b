"""Smooth dielectric interface (glass): Fresnel reflection and refraction, both delta.

The normal's side (the triangle winding) is the outside, of index 1; the
inside has index ``ior``: a number, or a dispersion law (:class:`Cauchy`,
:class:`Sellmeier`) giving the index per wavelength.  A sample reflects with
probability F (the exact dielectric Fresnel term) and refracts otherwise
(Snell's law), so both weights are 1, except that radiance crossing into a
medium of relative index eta is scaled by 1 / eta^2 (Veach 1997, sec. 5.2):
in "radiance" mode the refracted weight is 1 / eta^2; in "importance" mode
(light paths) it is 1.  Total internal reflection reflects always.

Dispersion: in spectral rendering the index, and so the refracted direction,
depends on the wavelength; the path follows its hero wavelength (the first
of its four) and the others are terminated: their weights become 0 and the
sample reports ``terminated``, on which the integrator makes the hero stand
for all four wavelengths once per path (Wilkie et al. 2014; pbrt-v4's
TerminateSecondary; see ``SpectralMode.terminate_secondary``).  RGB rendering
uses the index at 550 nm.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Union

import numpy as np

from ..spectra import WAVELENGTHS_PER_PATH, Cauchy, Sellmeier
from .base import BSDFSample, Surface
from .fresnel import fresnel_dielectric

__all__ = ["Dielectric", "REFERENCE_WAVELENGTH"]

REFERENCE_WAVELENGTH = 550.0  # nm: the index used when rendering in RGB
Index = Union[float, Cauchy, Sellmeier]


@dataclass
class DielectricParams:
    ior: np.ndarray         # (N,) interior index at the hero wavelength, relative to the exterior
    dispersive: np.ndarray  # (N,) bool: terminate secondary wavelengths
    channels: int


@dataclass(frozen=True)
class Dielectric:
    """Glass with interior index of refraction ``ior`` (a number > 0, or a Cauchy or Sellmeier law)."""

    ior: Index = 1.5
    kind = "dielectric"
    delta = True
    albedo = 1.0  # lossless: what is not reflected is transmitted

    def __post_init__(self) -> None:
        if isinstance(self.ior, (Cauchy, Sellmeier)):
            return
        if not (isinstance(self.ior, (int, float)) and np.isfinite(self.ior) and self.ior > 0):
            raise ValueError(f"ior: expected a number > 0 or a dispersion law, got {self.ior!r}")

    @classmethod
    def from_fields(cls, fields) -> "Dielectric":
        """A material table of type "dielectric": ``ior``, a number > 0 (default 1.5) or a dispersion law,
        ``{ cauchy = [a, b] }`` or ``{ sellmeier = { b = [...], c = [...] } }``."""
        ior = _ior(fields)
        fields.finish()
        return fields.build(lambda: cls(ior))

    @property
    def dispersive(self) -> bool:
        """Whether the index depends on the wavelength."""
        return isinstance(self.ior, (Cauchy, Sellmeier))

    def index(self, wavelength_nm: np.ndarray) -> np.ndarray:
        """Interior index at the given wavelengths."""
        if self.dispersive:
            return self.ior(wavelength_nm)
        return np.full(np.shape(wavelength_nm), float(self.ior))

    @staticmethod
    def tables(materials: list["Dielectric"]) -> dict:
        return {"materials": list(materials),
                "ior_reference": np.array([m.index(REFERENCE_WAVELENGTH) for m in materials], dtype=np.float64),
                "dispersive": np.array([m.dispersive for m in materials], dtype=bool)}

    @staticmethod
    def gather(tables, ids, colours, options) -> DielectricParams:
        count = ids.size
        if colours.wavelengths is None or not tables["dispersive"].any():
            return DielectricParams(tables["ior_reference"].take(ids), np.zeros(count, dtype=bool), colours.channels)
        hero = colours.wavelengths[0]
        ior = np.empty(count)
        for m, material in enumerate(tables["materials"]):
            lanes = np.flatnonzero(ids == m)
            if lanes.size:
                ior[lanes] = material.index(hero.take(lanes))
        return DielectricParams(ior, tables["dispersive"].take(ids), colours.channels)

    @staticmethod
    def eval(params: DielectricParams, surface: Surface, wi) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros((params.channels, wi.shape[1])), np.zeros(wi.shape[1])

    @staticmethod
    def sample(params: DielectricParams, surface: Surface, u, mode="radiance") -> BSDFSample:
        eta = np.where(surface.outside, params.ior, 1.0 / params.ior)  # eta_t / eta_i: entering from outside
        n_f = surface.n.astype(np.float64)                            # normal on the side of wo
        cos_i = surface.cos_o.astype(np.float64)
        fresnel, cos_t = fresnel_dielectric(cos_i, eta)
        reflects = u[0] < fresnel
        w = surface.wo.astype(np.float64)
        reflected = 2.0 * cos_i * n_f - w
        refracted = -w / eta + (cos_i / eta - cos_t) * n_f
        wi = np.where(reflects, reflected, refracted)
        wi /= np.sqrt(wi[0] ** 2 + wi[1] ** 2 + wi[2] ** 2)
        pdf = np.where(reflects, fresnel, 1.0 - fresnel)
        scale = np.ones_like(eta) if mode == "importance" else 1.0 / (eta * eta)
        count = wi.shape[1]
        weight = np.repeat(np.where(reflects, 1.0, scale)[None, :], params.channels, axis=0)
        terminated = None
        if params.dispersive.any() and params.channels == WAVELENGTHS_PER_PATH:
            weight[1:] *= ~params.dispersive
            terminated = params.dispersive
        return BSDFSample(wi.astype(np.float32), weight, pdf, np.ones(count, dtype=bool), terminated,
                          np.where(reflects, 1.0, eta))


def _ior(fields) -> Index:
    value = fields.raw("ior", 1.5)
    if not isinstance(value, dict):
        return fields.number("ior", 1.5, low=0.0, low_open=True)
    law = fields.sub("ior")
    if not (law.has("cauchy") or law.has("sellmeier")):
        raise fields.error("expected a number > 0 or a dispersion law: { cauchy = [a, b] } or "
                           "{ sellmeier = { b = [...], c = [...] } }", "ior")
    if law.has("cauchy"):
        a, b = law.vector("cauchy", 2)
        result = law.build(lambda: Cauchy(float(a), float(b)))
    else:
        sellmeier = law.sub("sellmeier")
        b, c = sellmeier.vector("b", 3), sellmeier.vector("c", 3)
        sellmeier.finish()
        result = law.build(lambda: Sellmeier(tuple(b), tuple(c)))
    law.finish()
    return result
