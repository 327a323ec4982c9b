"""Perfect mirror: a delta reflection with RGB reflectance, two-sided.

It is never evaluated for a given pair of directions (f is a Dirac delta):
``eval`` returns zero, and estimators cannot connect through it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..spectra import Colour, ColourTable, check_colour
from .base import BSDFSample, Surface, reflect

__all__ = ["Mirror"]


@dataclass
class MirrorParams:
    reflectance: np.ndarray  # (C, N)


@dataclass(frozen=True)
class Mirror:
    """Delta mirror with ``reflectance`` (RGB in [0, 1], or a spectrum <= 1)."""

    reflectance: Colour = (1.0, 1.0, 1.0)
    kind = "mirror"
    delta = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "reflectance", check_colour(self.reflectance, "reflectance", "reflectance"))

    @classmethod
    def from_fields(cls, fields) -> "Mirror":
        """A material table of type "mirror": ``reflectance`` (default white)."""
        reflectance = fields.colour("reflectance", [1.0, 1.0, 1.0])
        fields.finish()
        return fields.build(lambda: cls(reflectance))

    @property
    def albedo(self) -> float:
        """Largest fraction of light it reflects (the largest channel of its reflectance)."""
        return float(ColourTable([self.reflectance], "reflectance").rgb.max())

    @staticmethod
    def tables(materials: list["Mirror"]) -> dict:
        return {"reflectance": ColourTable([m.reflectance for m in materials], "reflectance")}

    @staticmethod
    def gather(tables, ids, colours, options) -> MirrorParams:
        return MirrorParams(colours.lookup(tables["reflectance"], ids))

    @staticmethod
    def eval(params: MirrorParams, surface: Surface, wi) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros_like(params.reflectance), np.zeros(wi.shape[1])

    @staticmethod
    def sample(params: MirrorParams, surface: Surface, u, mode="radiance") -> BSDFSample:
        wi = reflect(surface.wo, surface.n, surface.cos_o)
        count = wi.shape[1]
        return BSDFSample(wi.astype(np.float32), params.reflectance, np.ones(count), np.ones(count, dtype=bool))
