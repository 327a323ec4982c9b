"""Warps from the unit square to sampling domains, each with its density.

Inputs are uniform numbers in [0, 1) as (2, N) arrays; outputs are (3, N)
float32 unit directions, or barycentrics.  Direction warps have a matching
``_pdf`` function giving their solid-angle density; the triangle warp is
uniform in area (density 1 / area).
"""
from __future__ import annotations

import numpy as np

from . import _native

__all__ = [
    "square_to_uniform_sphere",
    "square_to_uniform_sphere_pdf",
    "square_to_cosine_about",
    "square_to_uniform_triangle",
]

INV_PI = 1.0 / np.pi
INV_TWO_PI = 0.5 / np.pi
INV_FOUR_PI = 0.25 / np.pi


def azimuth(u1: np.ndarray) -> np.ndarray:
    """The angle 2 pi u1 about the sphere's axis, float32, as both sphere warps compute it."""
    return np.float32(2 * np.pi) * u1.astype(np.float32)


def square_to_uniform_sphere(u: np.ndarray) -> np.ndarray:
    """Directions with the uniform density 1/(4 pi) over the unit sphere (Archimedes: z uniform in [-1, 1])."""
    z = np.float32(1) - np.float32(2) * u[0].astype(np.float32)
    r = np.sqrt(np.maximum(np.float32(0), np.float32(1) - z * z))
    phi = azimuth(u[1])
    return np.stack((r * np.cos(phi), r * np.sin(phi), z))


def square_to_uniform_sphere_pdf(v: np.ndarray) -> np.ndarray:
    """Solid-angle density of :func:`square_to_uniform_sphere`."""
    return np.full(v.shape[1], INV_FOUR_PI)


def square_to_cosine_about(n: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Directions with density max(cos, 0) / pi about unit normals n (3, N), without a tangent frame:
    n plus the uniform point of the unit sphere :func:`square_to_uniform_sphere` makes of u, normalised
    (Archimedes' hat-box theorem; n itself where the sum vanishes, probability 0).  One C pass
    (``ext/warp.c``) but for the angle's cosine and sine, which NumPy computes as the sphere's warp does."""
    phi = azimuth(u[1])
    return _native.cosine_about(np.ascontiguousarray(n, np.float32), np.ascontiguousarray(u[0], np.float64),
                                np.cos(phi), np.sin(phi))


def square_to_uniform_triangle(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Barycentrics (b1, b2) uniform over a triangle: p = (1-b1-b2) p0 + b1 p1 + b2 p2.

    Square-root parametrisation (Shirley & Chiu / pbrt-v3 UniformSampleTriangle);
    the area density is 1/area of the triangle.
    """
    su = np.sqrt(u[0])
    return su * (1.0 - u[1]), su * u[1]
