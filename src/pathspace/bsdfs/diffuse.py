"""Lambertian reflection: f = albedo / pi, two-sided.

Sampling techniques (estimator option ``diffuse_sampling``): ``"cosine"``
(density cos(theta)/pi; the sample weight is the albedo) or ``"uniform"``
over the hemisphere (density 1/(2 pi); weight 2 albedo cos(theta)).  Both
are built without a tangent frame: n + a uniform point on the unit sphere,
normalised, is cosine-distributed about n (Archimedes' hat-box theorem);
a uniform sphere point flipped to n's side is uniform on the hemisphere.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import warp
from ..spectra import Colour, ColourTable, check_colour
from .base import BSDFSample, Surface

__all__ = ["Diffuse", "SAMPLING"]

SAMPLING = ("cosine", "uniform")


@dataclass
class DiffuseParams:
    albedo: np.ndarray      # (C, N)
    technique: str


@dataclass(frozen=True)
class Diffuse:
    """Lambertian reflector with albedo ``reflectance`` (RGB in [0, 1], or a spectrum <= 1)."""

    reflectance: Colour
    kind = "diffuse"
    delta = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "reflectance", check_colour(self.reflectance, "reflectance", "reflectance"))

    @classmethod
    def from_fields(cls, fields) -> "Diffuse":
        """A material table of type "diffuse": ``reflectance``."""
        reflectance = fields.colour("reflectance")
        fields.finish()
        return fields.build(lambda: cls(reflectance))

    @property
    def albedo(self) -> float:
        """Largest fraction of light it reflects (the largest channel of its reflectance)."""
        return float(ColourTable([self.reflectance], "reflectance").rgb.max())

    @staticmethod
    def tables(materials: list["Diffuse"]) -> dict:
        """Parameter tables over the given materials."""
        return {"reflectance": ColourTable([m.reflectance for m in materials], "reflectance")}

    @staticmethod
    def gather(tables, ids: np.ndarray, colours, options) -> DiffuseParams:
        """Per-lane parameters."""
        return DiffuseParams(colours.lookup(tables["reflectance"], ids), options.get("diffuse_sampling", "cosine"))

    @staticmethod
    def cos_pdf(params: DiffuseParams, cos_i: np.ndarray) -> np.ndarray:
        """Solid-angle pdf of the sampling technique at cos_i = dot(n, wi) on the side of wo."""
        if params.technique == "uniform":
            return np.where(cos_i > 0, warp.INV_TWO_PI, 0.0)
        return np.maximum(cos_i, 0).astype(np.float64) * warp.INV_PI

    @staticmethod
    def eval(params: DiffuseParams, surface: Surface, wi) -> tuple[np.ndarray, np.ndarray]:
        """(f |cos theta_i|, pdf)."""
        n_f = surface.n
        cos_i = n_f[0] * wi[0] + n_f[1] * wi[1] + n_f[2] * wi[2]
        cos_over_pi = np.maximum(cos_i, 0).astype(np.float64) * warp.INV_PI
        pdf = cos_over_pi if params.technique == "cosine" else Diffuse.cos_pdf(params, cos_i)
        return params.albedo * cos_over_pi, pdf

    @staticmethod
    def sample(params: DiffuseParams, surface: Surface, u, mode="radiance") -> BSDFSample:
        """A direction by the chosen technique."""
        n_f = surface.n
        if params.technique == "uniform":
            sphere = warp.square_to_uniform_sphere(u[1:3])
            side = np.copysign(np.float32(1), n_f[0] * sphere[0] + n_f[1] * sphere[1] + n_f[2] * sphere[2])
            wi = sphere * side
            cos_i = np.abs(n_f[0] * wi[0] + n_f[1] * wi[1] + n_f[2] * wi[2]).astype(np.float64)
            weight = params.albedo * (2.0 * cos_i)
            pdf = np.full(cos_i.shape, warp.INV_TWO_PI)
        else:
            wi = warp.square_to_cosine_about(n_f, u[1:3])
            pdf = np.maximum(n_f[0] * wi[0] + n_f[1] * wi[1] + n_f[2] * wi[2], 0).astype(np.float64) * warp.INV_PI
            weight = params.albedo
        return BSDFSample(wi, weight, pdf, np.zeros(pdf.shape, dtype=bool))
