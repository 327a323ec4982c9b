"""The interface every scattering model implements, and helpers they share.

A *model* (one module per kind: diffuse, phong, mirror, dielectric,
conductor) is a frozen dataclass holding one material's scene parameters,
plus vectorised class methods that work on lanes that all use that kind:

``gather(materials, ids, colours, options)``
    Per-lane parameters for lanes using ``materials[ids]``.  ``colours``
    turns (3, M) RGB tables into per-lane (C, N) values (RGB: C = 3; spectral
    rendering evaluates spectra at the lanes' wavelengths); ``options`` are
    estimator settings the model reads (``diffuse_sampling``).
``eval(params, n, wo, wi)``
    (f(wo, wi) |cos theta_i| as (C, N) float64, pdf of sampling wi given wo in
    solid angle as (N,) float64).  Delta models return zeros.
``sample(params, n, wo, u, mode)``
    A :class:`BSDFSample` from three uniforms per lane.

Geometry: ``n`` is the unit geometric normal (3, N) float32 as stored (its
side set by the triangle's winding), ``wo`` and ``wi`` unit directions away
from the surface.  Models that do not transmit are two-sided: they act on
the side of ``wo``.  ``mode`` is "radiance" for paths traced from the camera
and "importance" for paths traced from lights (only refraction differs).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BSDFSample", "MODES", "face_forward", "reflect"]

MODES = ("radiance", "importance")


@dataclass
class BSDFSample:
    """A sampled direction per lane.

    ``wi`` (3, N) float32 unit direction; ``weight`` (C, N) float64 =
    f |cos theta_i| / pdf (zero for failed samples); ``pdf`` (N,) float64
    solid-angle density (for delta lobes: the discrete probability of the
    chosen lobe); ``delta`` (N,) bool, whether the sampled lobe is a delta
    (its pdf is not a density and it cannot be reached by other strategies).
    """

    wi: np.ndarray
    weight: np.ndarray
    pdf: np.ndarray
    delta: np.ndarray


def face_forward(n: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The normal turned to the side of w, and dot(n, w) as seen from that side (>= 0)."""
    cos = n[0] * w[0] + n[1] * w[1] + n[2] * w[2]
    sign = np.copysign(np.float32(1), cos)
    return n * sign, np.abs(cos)


def reflect(w: np.ndarray, n: np.ndarray, cos: np.ndarray) -> np.ndarray:
    """Mirror direction of w about n, given cos = dot(n, w): 2 cos n - w."""
    return 2 * cos * n - w
