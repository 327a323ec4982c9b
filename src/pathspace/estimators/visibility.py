"""Shadow rays: whether segments between points, or rays toward light samples, are blocked.

Segments run between their end points moved off their surfaces by each surface's error bound
(see :func:`pathspace.vecmath.shadow_ray`), along the line between the two points, so that the
point pairs the estimators weigh are the ones tested.  The rays are built in C
(:meth:`pathspace.accel.Accel.occluded_between`, bit for bit the NumPy reference's), except toward
lights at infinity.
"""
from __future__ import annotations

import numpy as np

from ..vecmath import RAY_TMIN, offset_origin, shadow_ray

__all__ = ["segment_blocked", "light_sample_blocked"]


def segment_blocked(scene, a: np.ndarray, eps_a: np.ndarray, n_a: np.ndarray, b: np.ndarray, eps_b: np.ndarray,
                    n_b: np.ndarray, lanes: np.ndarray | None = None, b_lanes: np.ndarray | None = None) -> np.ndarray:
    """Whether geometry lies between points ``a`` and ``b`` (3, N) float32; ``eps_*`` are the error bounds
    of the surfaces they lie on (0 off surfaces) and ``n_*`` those surfaces' normals; for the segments
    ``lanes`` (int64 indices, (M,)) only, if given, and with their ends at ``b_lanes`` of ``b``, ``eps_b`` and
    ``n_b`` (default: the same lanes; given, b's arrays may have another width than a's)."""
    return scene.accel.occluded_between(a, n_a, eps_a, b, n_b, eps_b, lanes, b_lanes, threads=1)


def light_sample_blocked(scene, p: np.ndarray, eps: np.ndarray, n: np.ndarray, ls, lanes: np.ndarray) -> np.ndarray:
    """Whether the segments from receivers ``p`` (with error bounds ``eps`` and normals ``n``, all full
    width) to the light samples ``ls`` are blocked, for the lanes ``lanes``.  Rays toward infinite lights
    have no end (their samples' points are zeros: the segments computed for them are replaced)."""
    finite = np.isfinite(ls.distance.take(lanes))
    if finite.all():
        return scene.accel.occluded_between(p, n, eps, ls.point, ls.normal, ls.epsilon, lanes, threads=1)
    start, normal, epsilon = np.take(p, lanes, axis=1), np.take(n, lanes, axis=1), eps.take(lanes)
    origin, direction, tmax = shadow_ray(start, normal, epsilon, np.take(ls.point, lanes, axis=1),
                                         np.take(ls.normal, lanes, axis=1), ls.epsilon.take(lanes))
    wi = np.take(ls.wi, lanes, axis=1)
    origin = np.where(finite, origin, offset_origin(start, normal, epsilon, wi))
    direction, tmax = np.where(finite, direction, wi), np.where(finite, tmax, np.float32(np.inf))
    return scene.accel.occluded(origin, direction, RAY_TMIN, tmax, threads=1)
