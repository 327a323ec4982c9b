"""Shadow rays: whether segments between points, or rays toward light samples, are blocked.

Segments leave the surface at their start and stop short of the surface at
their end by each surface's ray offset (see :func:`pathspace.vecmath.leave_distance`),
along the exact line between the two points, so that the point pairs the
estimators weigh are the ones tested.
"""
from __future__ import annotations

import numpy as np

from ..vecmath import dot, segment_span

__all__ = ["segment_blocked", "light_sample_blocked"]


def segment_blocked(scene, a: np.ndarray, eps_a: np.ndarray, n_a: np.ndarray, b: np.ndarray, eps_b: np.ndarray,
                    n_b: np.ndarray) -> np.ndarray:
    """Whether geometry lies between points ``a`` and ``b`` (3, N) float32; ``eps_*`` are the offsets of
    the surfaces they lie on (0 off surfaces) and ``n_*`` those surfaces' normals."""
    d = b - a
    length = np.sqrt(dot(d, d))
    with np.errstate(divide="ignore", invalid="ignore"):
        w = d / length
    tmin, tmax = segment_span(eps_a, dot(n_a, w), eps_b, dot(n_b, w), length)
    return scene.accel.occluded(np.ascontiguousarray(a, dtype=np.float32), np.ascontiguousarray(d, dtype=np.float32),
                                tmin, tmax, threads=1)


def light_sample_blocked(scene, p: np.ndarray, eps: np.ndarray, n: np.ndarray, ls, lanes: np.ndarray) -> np.ndarray:
    """Whether the segments from receivers ``p`` (with offsets ``eps`` and normals ``n``, all full width) to
    the light samples ``ls`` are blocked, for the lanes ``lanes``.  Rays toward infinite lights have no end."""
    start = np.take(p, lanes, axis=1)
    wi = np.take(ls.wi, lanes, axis=1)
    distance = ls.distance.take(lanes)
    cos_start = dot(np.take(n, lanes, axis=1), wi)
    finite = np.isfinite(distance)
    length = np.where(finite, distance, 1.0)
    tmin, tmax = segment_span(eps.take(lanes), cos_start, ls.epsilon.take(lanes), ls.cos_light.take(lanes), length)
    if finite.all():
        return scene.accel.occluded(start, np.take(ls.point, lanes, axis=1) - start, tmin, tmax, threads=1)
    direction = np.where(finite, np.take(ls.point, lanes, axis=1) - start, wi)
    return scene.accel.occluded(start, direction, tmin, np.where(finite, tmax, np.inf), threads=1)
