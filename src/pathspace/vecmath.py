"""Vector helpers for structure-of-arrays geometry.

Vectors are (3, N) arrays: one contiguous row per coordinate, so that a dot
product is three multiplies and two adds over contiguous memory (several
times faster in NumPy than reducing an (N, 3) array).  Geometry (points,
directions, normals) is float32, as Embree traces it; throughputs, pdfs and
weights are float64 and live elsewhere.
"""
from __future__ import annotations

import numpy as np

__all__ = ["dot", "orthonormal_basis", "Frame", "offset_along"]


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


def offset_along(p: np.ndarray, n: np.ndarray, side: np.ndarray, epsilon: float) -> np.ndarray:
    """Points p moved by ``epsilon`` along the unit normals n, to the side where ``side`` > 0.

    Used to start rays off a surface so they cannot re-hit it: ``side`` is the
    dot product of the normal with the direction the ray will leave in.
    """
    step = np.where(side > 0, np.float32(epsilon), np.float32(-epsilon))
    return p + n * step
