"""Scattering models (BSDFs), vectorised over wavefronts.

Scene side: each material is a small frozen dataclass (:class:`Diffuse`);
a scene's materials form a :class:`MaterialTable` of per-material parameter
arrays, indexed by the material id stored per triangle.

Estimator side: each model has vectorised functions over lanes that all use
it, in world space: ``n`` is the unit geometric normal turned toward the
outgoing direction ``wo`` (directions point away from the surface), so
two-sided models need no flips.  For the Lambertian model, f |cos theta_i|
is the albedo (a per-lane colour) times a scalar, and the two are kept apart
so that colour arithmetic happens once per lane.

The diffuse model is two-sided: it reflects on whichever side wo lies and
never transmits.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import warp

__all__ = ["Diffuse", "MaterialTable", "diffuse_cos_over_pi", "diffuse_sample"]


@dataclass(frozen=True)
class Diffuse:
    """Lambertian reflector with RGB albedo ``reflectance`` (each component in [0, 1])."""

    reflectance: tuple[float, float, float]
    kind = "diffuse"

    def __post_init__(self) -> None:
        r = np.asarray(self.reflectance, dtype=np.float64)
        if r.shape != (3,) or not np.all(np.isfinite(r)) or np.any(r < 0) or np.any(r > 1):
            raise ValueError(f"reflectance: expected 3 numbers in [0, 1], got {self.reflectance!r}")


class MaterialTable:
    """The materials of a scene, as parameter arrays indexed by material id.

    Attributes
    ----------
    names : material names, in id order
    materials : the material descriptions
    reflectance : (3, M) float64, RGB albedo of each material
    """

    def __init__(self, names: list[str], materials: list[Diffuse]) -> None:
        if len(names) != len(materials):
            raise ValueError("one name per material is required")
        self.names = list(names)
        self.materials = list(materials)
        self.reflectance = np.array([m.reflectance for m in materials], dtype=np.float64).reshape(-1, 3).T.copy()

    def __len__(self) -> int:
        return len(self.materials)

    def __repr__(self) -> str:
        return "MaterialTable(" + ", ".join(f"{n}={m}" for n, m in zip(self.names, self.materials)) + ")"


def diffuse_cos_over_pi(cos_i: np.ndarray) -> np.ndarray:
    """The scalar part of a Lambertian f |cos theta_i| = albedo * max(cos_i, 0) / pi, as float64.

    ``cos_i`` = dot(n, wi) with n on the side of wo; it is also the solid-angle
    density of :func:`diffuse_sample`.
    """
    return np.maximum(cos_i, 0).astype(np.float64) * warp.INV_PI


def diffuse_sample(n: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cosine-weighted direction about n (the normal on the side of wo), and its solid-angle pdf.

    The sample weight f |cos| / pdf is the albedo.  Uses the fact that n + (a
    uniform point on the unit sphere), normalised, is cosine distributed about
    n (Archimedes' hat-box theorem), which needs no tangent frame.
    """
    wi = n + warp.square_to_uniform_sphere(u)
    length = np.sqrt(wi[0] * wi[0] + wi[1] * wi[1] + wi[2] * wi[2])
    # The sum vanishes only when the sphere point is exactly -n (probability 0).
    wi = np.where(length > 1e-6, wi / np.maximum(length, np.float32(1e-6)), n)
    return wi, diffuse_cos_over_pi(wi[0] * n[0] + wi[1] * n[1] + wi[2] * n[2])
