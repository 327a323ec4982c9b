"""Shadow rays: whether segments between points, or rays toward light samples, are blocked.

Segments run between their end points moved off their surfaces by each surface's error bound
(see :func:`pathspace.vecmath.shadow_ray`), along the line between the two points, so that the
point pairs the estimators weigh are the ones tested.
"""
from __future__ import annotations

import numpy as np

from ..vecmath import offset_origin, shadow_ray

__all__ = ["segment_blocked", "light_sample_blocked"]


def segment_blocked(scene, a: np.ndarray, eps_a: np.ndarray, n_a: np.ndarray, b: np.ndarray, eps_b: np.ndarray,
                    n_b: np.ndarray) -> np.ndarray:
    """Whether geometry lies between points ``a`` and ``b`` (3, N) float32; ``eps_*`` are the error bounds
    of the surfaces they lie on (0 off surfaces) and ``n_*`` those surfaces' normals."""
    origin, direction, tmax = shadow_ray(a, n_a, eps_a, b, n_b, eps_b)
    return scene.accel.occluded(origin, direction, 0.0, tmax, threads=1)


def light_sample_blocked(scene, p: np.ndarray, eps: np.ndarray, n: np.ndarray, ls, lanes: np.ndarray) -> np.ndarray:
    """Whether the segments from receivers ``p`` (with error bounds ``eps`` and normals ``n``, all full
    width) to the light samples ``ls`` are blocked, for the lanes ``lanes``.  Rays toward infinite lights
    have no end."""
    start, normal, epsilon = np.take(p, lanes, axis=1), np.take(n, lanes, axis=1), eps.take(lanes)
    finite = np.isfinite(ls.distance.take(lanes))
    blocked = np.empty(lanes.size, dtype=bool)
    near = np.flatnonzero(finite)
    if near.size:
        k = lanes.take(near)
        origin, direction, tmax = shadow_ray(np.take(start, near, axis=1), np.take(normal, near, axis=1),
                                             epsilon.take(near), np.take(ls.point, k, axis=1),
                                             np.take(ls.normal, k, axis=1), ls.epsilon.take(k))
        blocked[near] = scene.accel.occluded(origin, direction, 0.0, tmax, threads=1)
    far = np.flatnonzero(~finite)
    if far.size:
        wi = np.take(ls.wi, lanes.take(far), axis=1)
        origin = offset_origin(np.take(start, far, axis=1), np.take(normal, far, axis=1), epsilon.take(far), wi)
        blocked[far] = scene.accel.occluded(origin, wi, 0.0, np.inf, threads=1)
    return blocked
