"""Smooth dielectric interface (glass): Fresnel reflection and refraction, both delta.

The normal's side (the triangle winding) is the outside, of index 1; the
inside has index ``ior``.  A sample reflects with probability F (the exact
dielectric Fresnel term) and refracts otherwise (Snell's law), so both
weights are 1, except that radiance crossing into a medium of relative
index eta is scaled by 1 / eta^2 (Veach 1997, sec. 5.2): in "radiance" mode
the refracted weight is 1 / eta^2; in "importance" mode (light paths) it is 1.
Total internal reflection reflects always.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import BSDFSample, Surface
from .fresnel import fresnel_dielectric

__all__ = ["Dielectric"]


@dataclass
class DielectricParams:
    ior: np.ndarray  # (N,) interior index relative to the exterior
    channels: int


@dataclass(frozen=True)
class Dielectric:
    """Glass with interior index of refraction ``ior`` (> 0, != 1 is not required)."""

    ior: float = 1.5
    kind = "dielectric"
    delta = True

    def __post_init__(self) -> None:
        if not (np.isfinite(self.ior) and self.ior > 0):
            raise ValueError(f"ior: expected a number > 0, got {self.ior!r}")

    @staticmethod
    def tables(materials: list["Dielectric"]) -> dict[str, np.ndarray]:
        return {"ior": np.array([m.ior for m in materials], dtype=np.float64)}

    @staticmethod
    def gather(tables, ids, colours, options) -> DielectricParams:
        return DielectricParams(tables["ior"].take(ids), colours.channels)

    @staticmethod
    def eval(params: DielectricParams, surface: Surface, wi) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros((params.channels, wi.shape[1])), np.zeros(wi.shape[1])

    @staticmethod
    def sample(params: DielectricParams, surface: Surface, u, mode="radiance") -> BSDFSample:
        eta = np.where(surface.outside, params.ior, 1.0 / params.ior)  # eta_t / eta_i: entering from outside
        n_f = surface.n.astype(np.float64)                            # normal on the side of wo
        cos_i = surface.cos_o.astype(np.float64)
        wo = surface.wo
        fresnel, cos_t = fresnel_dielectric(cos_i, eta)
        reflects = u[0] < fresnel
        w = wo.astype(np.float64)
        reflected = 2.0 * cos_i * n_f - w
        refracted = -w / eta + (cos_i / eta - cos_t) * n_f
        wi = np.where(reflects, reflected, refracted)
        wi /= np.sqrt(wi[0] ** 2 + wi[1] ** 2 + wi[2] ** 2)
        pdf = np.where(reflects, fresnel, 1.0 - fresnel)
        scale = np.ones_like(eta) if mode == "importance" else 1.0 / (eta * eta)
        weight = np.where(reflects, 1.0, scale)
        count = wi.shape[1]
        return BSDFSample(wi.astype(np.float32), np.broadcast_to(weight, (params.channels, count)).copy(), pdf,
                          np.ones(count, dtype=bool))
