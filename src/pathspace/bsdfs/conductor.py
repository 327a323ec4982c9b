"""Rough conductor: GGX microfacet reflection with the exact conductor Fresnel term, two-sided.

f(wo, wi) = D(h) G2(wo, wi) F(wo.h) / (4 cos theta_o cos theta_i)
(Walter et al. 2007, eq. 20), sampled through the visible normals (Heitz
2018), so that the sample weight is F G2 / G1(wo).  ``alpha`` is the GGX
roughness, from 1e-4 (nearly a mirror) to 1; ``eta`` and ``k`` the RGB
complex index of refraction (e.g. gold: eta = [0.143, 0.374, 1.442],
k = [3.983, 2.385, 1.603]).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..spectra import Colour, ColourTable, check_colour
from ..vecmath import Frame
from .base import BSDFSample, Surface
from .fresnel import fresnel_conductor
from .microfacet import ggx_d, sample_visible_normal, smith_g1, smith_g2, visible_normal_pdf

__all__ = ["Conductor"]

ALPHA_RANGE = (1e-4, 1.0)


@dataclass
class ConductorParams:
    eta: np.ndarray    # (C, N)
    k: np.ndarray      # (C, N)
    alpha: np.ndarray  # (N,)


@dataclass(frozen=True)
class Conductor:
    """GGX conductor with complex index ``eta`` + i ``k`` (RGB triples or spectra) and roughness ``alpha``."""

    eta: Colour
    k: Colour
    alpha: float
    kind = "conductor"
    delta = False

    def __post_init__(self) -> None:
        for name in ("eta", "k"):
            object.__setattr__(self, name, check_colour(getattr(self, name), name, "unbounded"))
        if not (ALPHA_RANGE[0] <= float(self.alpha) <= ALPHA_RANGE[1]):
            raise ValueError(f"alpha: expected a GGX roughness in [{ALPHA_RANGE[0]:g}, {ALPHA_RANGE[1]:g}], "
                             f"got {self.alpha!r}")

    @classmethod
    def from_fields(cls, fields) -> "Conductor":
        """A material table of type "conductor": ``eta``, ``k``, ``alpha``."""
        args = fields.colour("eta"), fields.colour("k"), fields.number("alpha")
        fields.finish()
        return fields.build(lambda: cls(*args))

    albedo = 1.0  # a bound: a conductor reflects up to all light at grazing angles

    @staticmethod
    def tables(materials: list["Conductor"]) -> dict:
        return {"eta": ColourTable([m.eta for m in materials], "unbounded"),
                "k": ColourTable([m.k for m in materials], "unbounded"),
                "alpha": np.array([m.alpha for m in materials], dtype=np.float64)}

    @staticmethod
    def gather(tables, ids, colours, options) -> ConductorParams:
        return ConductorParams(colours.lookup(tables["eta"], ids), colours.lookup(tables["k"], ids),
                               tables["alpha"].take(ids))

    @staticmethod
    def eval(params: ConductorParams, surface: Surface, wi) -> tuple[np.ndarray, np.ndarray]:
        frame = Frame(surface.n)
        lo, li = frame.to_local(surface.wo), frame.to_local(wi)
        h = lo + li
        length = np.sqrt(h[0] ** 2 + h[1] ** 2 + h[2] ** 2)
        valid = (lo[2] > 0) & (li[2] > 0) & (length > 0)
        h = h / np.where(length > 0, length, 1.0)
        alpha = params.alpha
        d = ggx_d(h, alpha)
        cos_oh = np.abs(lo[0] * h[0] + lo[1] * h[1] + lo[2] * h[2])
        f_fresnel = fresnel_conductor(cos_oh, params.eta, params.k)
        with np.errstate(divide="ignore", invalid="ignore"):
            scalar = np.where(valid, d * smith_g2(lo, li, alpha) / (4.0 * lo[2]), 0.0)
            pdf = np.where(valid, visible_normal_pdf(lo, h, alpha) / (4.0 * cos_oh), 0.0)
        return f_fresnel * scalar, np.nan_to_num(pdf)

    @staticmethod
    def sample(params: ConductorParams, surface: Surface, u, mode="radiance") -> BSDFSample:
        frame = Frame(surface.n)
        lo = frame.to_local(surface.wo)
        alpha = params.alpha
        h = sample_visible_normal(lo, alpha, u[1:3])
        cos_oh = lo[0] * h[0] + lo[1] * h[1] + lo[2] * h[2]
        li = 2.0 * cos_oh * h - lo
        valid = (li[2] > 0) & (lo[2] > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            pdf = np.where(valid, visible_normal_pdf(lo, h, alpha) / (4.0 * np.abs(cos_oh)), 0.0)
            ratio = np.where(valid, smith_g2(lo, li, alpha) / smith_g1(lo, alpha), 0.0)
        weight = fresnel_conductor(np.abs(cos_oh), params.eta, params.k) * ratio
        wi = frame.to_world(li).astype(np.float32)
        return BSDFSample(wi, weight, np.nan_to_num(pdf), np.zeros(pdf.shape, dtype=bool))
