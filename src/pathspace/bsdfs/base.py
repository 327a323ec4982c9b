"""The interface every scattering model implements, and helpers they share.

A *model* (one module per kind: diffuse, phong, mirror, dielectric,
conductor) is a frozen dataclass holding one material's scene parameters,
plus vectorised class methods that work on lanes that all use that kind:

``gather(materials, ids, colours, options)``
    Per-lane parameters for lanes using ``materials[ids]``.  ``colours``
    turns (3, M) RGB tables into per-lane (C, N) values (RGB: C = 3; spectral
    rendering evaluates spectra at the lanes' wavelengths); ``options`` are
    estimator settings the model reads (``diffuse_sampling``).
``eval(params, surface, wi)``
    (f(wo, wi) |cos theta_i| as (C, N) float64, pdf of sampling wi given wo in
    solid angle as (N,) float64).  Delta models return zeros.
``sample(params, surface, u, mode)``
    A :class:`BSDFSample` from three uniforms per lane.

Geometry comes as a :class:`Surface`: the unit normal turned to the side of
the outgoing direction ``wo`` (directions point away from the surface), and
whether that is the side the geometric normal points to (``outside``; it
tells a dielectric whether light enters or leaves).  Models that do not
transmit are two-sided: they act on the side of ``wo``.  ``mode`` is
"radiance" for paths traced from the camera and "importance" for paths
traced from lights (only refraction differs).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

__all__ = ["BSDFSample", "MODES", "Surface", "reflect"]

MODES = ("radiance", "importance")


@dataclass
class BSDFSample:
    """A sampled direction per lane.

    ``wi`` (3, N) float32 unit direction; ``weight`` (C, N) float64 =
    f |cos theta_i| / pdf (zero for failed samples); ``pdf`` (N,) float64
    solid-angle density (for delta lobes: the discrete probability of the
    chosen lobe); ``delta`` (N,) bool, whether the sampled lobe is a delta
    (its pdf is not a density and it cannot be reached by other strategies);
    ``terminated`` (N,) bool or None: the sample kept only the hero wavelength;
    ``eta`` (N,) or None: the relative index of refraction eta_t / eta_i the
    sample crossed (1 where it reflected; None for models that never refract)
    -- radiance crossing it is scaled by 1 / eta^2, which Russian roulette
    undoes before it reads the throughput.
    """

    wi: np.ndarray
    weight: np.ndarray
    pdf: np.ndarray
    delta: np.ndarray
    terminated: np.ndarray | None = None  # (N,) bool: a dispersive interface terminated secondary wavelengths
    eta: np.ndarray | None = None


class Surface:
    """Shading geometry of N lanes seen along rays of direction ``direction`` (3, N) float32.

    ``n`` (3, N) float32 unit normal with dot(n, wo) >= 0, where ``wo`` =
    -direction (computed when first used); ``cos_o`` (N,) = dot(n, wo);
    ``outside`` (N,) bool: wo is on the side the geometric normal points to.
    """

    def __init__(self, n: np.ndarray, direction: np.ndarray, cos_o: np.ndarray, outside: np.ndarray) -> None:
        self.n, self.direction, self.cos_o, self.outside = n, direction, cos_o, outside

    @classmethod
    def facing(cls, normal: np.ndarray, direction: np.ndarray, cos: np.ndarray | None = None) -> "Surface":
        """The surface hit by rays ``direction``, given its geometric normal (and dot(normal, -direction))."""
        if cos is None:
            cos = -(normal[0] * direction[0] + normal[1] * direction[1] + normal[2] * direction[2])
        outside = cos >= 0
        return cls(normal * np.where(outside, np.float32(1), np.float32(-1)), direction, np.abs(cos), outside)

    @cached_property
    def wo(self) -> np.ndarray:
        """Unit directions toward where the rays came from (3, N) float32."""
        return -self.direction

    def take(self, idx: np.ndarray) -> "Surface":
        """The lanes ``idx``."""
        return Surface(np.take(self.n, idx, axis=1), np.take(self.direction, idx, axis=1), self.cos_o.take(idx),
                       self.outside.take(idx))


def reflect(w: np.ndarray, n: np.ndarray, cos: np.ndarray) -> np.ndarray:
    """Mirror direction of w about n, given cos = dot(n, w): 2 cos n - w."""
    return 2 * cos * n - w
