"""Vector helpers for structure-of-arrays geometry.

Vectors are (3, N) arrays: one contiguous row per coordinate, so that a dot
product is three multiplies and two adds over contiguous memory (several
times faster in NumPy than reducing an (N, 3) array).  Geometry (points,
directions, normals) is float32, as Embree traces it; throughputs, pdfs and
weights are float64 and live elsewhere.
"""
from __future__ import annotations

import numpy as np

__all__ = ["dot", "orthonormal_basis", "Frame", "gamma", "offset_origin", "shadow_ray", "FLOAT32_ROUNDOFF", "RAY_TMIN"]


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


# Floating-point error bounds (Higham 2002, sec. 3.1; pbrt-v4, sec. 6.8.1): with the unit roundoff u of
# float32, a result of n roundings is within gamma(n) = n u / (1 - n u) of its exact value, relatively.
FLOAT32_ROUNDOFF = 2.0 ** -24


def gamma(n: int) -> float:
    """pbrt's gamma_n = n u / (1 - n u) for float32's unit roundoff u = 2^-24."""
    return n * FLOAT32_ROUNDOFF / (1.0 - n * FLOAT32_ROUNDOFF)


# The far end o_a + 1 d of a shadow ray o_a -> o_b misses o_b by the rounding of d = o_b - o_a, and
# Embree's plane test at t ~ 1 computes (v - o_a) . n, of terms about as large as d: together, within this
# many roundings of sum_c |n_c| |d_c| along the far surface's normal n (the terms of the far triangle's own
# extent are within its error bound epsilon, by which o_b already stands off it).
SHADOW_END_ROUNDINGS = 4
# Rays start at their (offset) origins, but a hit *at* t = 0 is not taken (pbrt's t > 0): an origin that lies
# exactly in another surface's plane -- a point on one wall at the seam with another, moved along its own
# normal -- would find that surface at distance 0, a zero-length segment with an infinite geometry term
# (found at a seam of the Cornell box in ~1e8 light-walk rays: 27 connections of one lane dropped as NaN).
# The least normal float32 is above the t = -0.0 or 0 Embree reports there and below any real hit distance.
RAY_TMIN = np.float32(np.finfo(np.float32).tiny)


def offset_origin(p: np.ndarray, n: np.ndarray, epsilon: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Ray origins (3, N) float32 for rays leaving surface points ``p`` in directions ``w``: ``p`` moved by
    ``epsilon`` along the unit normals ``n``, to the side ``w`` points to (pbrt-v4's ``OffsetRayOrigin``,
    sec. 6.8.6).  ``epsilon`` bounds the error of ``p`` along ``n`` (see
    :class:`pathspace.scene.mesh.TriangleMesh`), so the origin lies on the right side of the true surface
    and the ray starts at t = 0 -- no offset along the ray, which would grow as 1 / |cos| at grazing
    angles.  Points off any surface (lights, the lens) have ``epsilon`` 0 and stay where they are."""
    side = np.where(dot(n, w) < 0, -epsilon, epsilon).astype(np.float32)
    return (p + n * side).astype(np.float32)


def shadow_ray(a: np.ndarray, n_a: np.ndarray, eps_a: np.ndarray, b: np.ndarray, n_b: np.ndarray,
               eps_b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(origin, direction, tmax) of the ray testing the segment between surface points ``a`` and ``b``
    (3, N) float32 with normals ``n_*`` and error bounds ``eps_*`` (0 off surfaces).

    Both ends are offset toward each other (pbrt-v4's ``SpawnRayTo``); the ray runs from the offset
    ``a`` (t = 0) to the offset ``b`` (t = 1).  Where ``b`` is on a surface, the ray's end point is
    itself only known to within a few roundings of d = o_b - o_a (see ``SHADOW_END_ROUNDINGS``), so the
    ray stops that far -- measured along ``b``'s normal -- short of it: tmax = 1 - slack / |d . n_b| with
    slack = gamma(4) sum_c |n_b,c| |d_c|.  The span left untested is the slab within eps_b + slack of
    ``b``'s surface, a few float32 roundings of the segment's length; it does not grow at grazing angles.
    """
    w = b - a
    origin = offset_origin(a, n_a, eps_a, w)
    end = offset_origin(b, n_b, eps_b, -w)
    direction = end - origin
    spread = np.abs(n_b[0] * direction[0]) + np.abs(n_b[1] * direction[1]) + np.abs(n_b[2] * direction[2])
    slack = np.where(eps_b > 0, gamma(SHADOW_END_ROUNDINGS) * spread, 0.0)
    across = np.abs(dot(direction, n_b))
    with np.errstate(divide="ignore", invalid="ignore"):
        tmax = np.where(slack > 0, 1.0 - slack / across, 1.0)
    return origin, direction, np.maximum(tmax, 0.0).astype(np.float32)
