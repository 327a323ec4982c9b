"""Vector helpers for structure-of-arrays geometry.

Vectors are (3, N) arrays: one contiguous row per coordinate, so that a dot
product is three multiplies and two adds over contiguous memory (several
times faster in NumPy than reducing an (N, 3) array).  Geometry (points,
directions, normals) is float32, as Embree traces it; throughputs, pdfs and
weights are float64 and live elsewhere.
"""
from __future__ import annotations

import numpy as np

__all__ = ["dot", "orthonormal_basis", "Frame", "leave_distance", "segment_span", "MIN_LEAVING_COS"]


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot product of two (3, N) arrays."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tangents (s, t) completing unit normals n to right-handed frames (s, t, n).

    Branchless construction of Duff et al., "Building an Orthonormal Basis,
    Revisited", JCGT 6(1), 2017, listing 3.
    """
    sign = np.copysign(np.ones_like(n[2]), n[2])
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    s = np.stack((1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]))
    t = np.stack((b, sign + n[1] * n[1] * a, -n[1]))
    return s, t


class Frame:
    """Orthonormal frames (s, t, n) around unit normals (3, N), for models defined in local coordinates."""

    def __init__(self, n: np.ndarray) -> None:
        self.n = n.astype(np.float64)
        self.s, self.t = orthonormal_basis(self.n)

    def to_local(self, v: np.ndarray) -> np.ndarray:
        """World vectors (3, N) in local coordinates, float64."""
        return np.stack((dot(v, self.s), dot(v, self.t), dot(v, self.n)))

    def to_world(self, v: np.ndarray) -> np.ndarray:
        """Local vectors (3, N) in world coordinates, float64."""
        return v[0] * self.s + v[1] * self.t + v[2] * self.n


# Rays leaving within this cosine of a surface's tangent plane start at the distance they would at
# this cosine: closer to grazing, epsilon / |cos| would skip geometry near the surface.
MIN_LEAVING_COS = 1e-3


def leave_distance(epsilon: np.ndarray, cos: np.ndarray) -> np.ndarray:
    """Distance (float32) along a ray leaving a surface at which it starts: epsilon / |cos| (see
    ``pathspace.scene.mesh.RAY_OFFSET_RELATIVE``); ``cos`` is between the ray and the surface normal."""
    return (epsilon / np.maximum(np.abs(cos), np.float32(MIN_LEAVING_COS))).astype(np.float32)


def segment_span(start_eps, start_cos, end_eps, end_cos, length) -> tuple[np.ndarray, np.ndarray]:
    """(tmin, tmax), as fractions of the segment, of a shadow ray p -> q that must not see the surfaces
    at either end; ``*_eps`` are the surfaces' ray offsets (0 at points off any surface, like point
    lights and lens points) and ``*_cos`` the cosines there; ``length`` = |q - p|."""
    with np.errstate(divide="ignore", invalid="ignore"):
        tmin = np.where(length > 0, leave_distance(start_eps, start_cos) / length, 0.0)
        tmax = np.where(length > 0, 1.0 - leave_distance(end_eps, end_cos) / length, 0.0)
    return tmin.astype(np.float32), tmax.astype(np.float32)
