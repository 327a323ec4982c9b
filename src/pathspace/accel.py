"""Ray traversal: the Embree 4 BVH of the C extension, over whole arrays of rays.

The Embree library is the one bundled in the ``embreex`` wheel.  It is found
through ``importlib.metadata`` and opened by the extension with ``dlopen`` on
first use; nothing else of embreex is imported.
"""
from __future__ import annotations

import importlib.metadata
from typing import NamedTuple

import numpy as np

from . import _native

__all__ = ["Accel", "Hits", "embree_library_path"]


class Hits(NamedTuple):
    """Closest hits of a batch of N rays (all arrays of length N).

    ``t`` is the distance along the (unnormalised) ray direction, ``inf`` on a
    miss; ``prim`` the triangle index, -1 on a miss; ``u``, ``v`` the
    barycentrics of the hit point ``(1-u-v) p0 + u p1 + v p2``; ``ng`` the
    unnormalised geometric normal ``(p1-p0) x (p2-p0)`` as a (3, N) array, or
    None when it was not requested.
    """

    t: np.ndarray
    prim: np.ndarray
    u: np.ndarray
    v: np.ndarray
    ng: np.ndarray | None


def embree_library_path() -> str:
    """Path of the Embree 4 shared library bundled in the installed embreex wheel."""
    try:
        files = importlib.metadata.files("embreex")
    except importlib.metadata.PackageNotFoundError:
        raise ImportError(
            "pathspace traces rays with the Embree 4 library bundled in the 'embreex' wheel, "
            "which is not installed: pip install embreex"
        ) from None
    candidates = [f for f in files or () if f.name.startswith("libembree4") and ".so" in f.name]
    if not candidates:
        raise ImportError(
            "the installed embreex wheel contains no libembree4 shared library "
            f"(looked through {len(files or ())} files); reinstall it: pip install --force-reinstall embreex"
        )
    return str(candidates[0].locate())


def _ensure_embree() -> None:
    if _native.embree_loaded() is None:
        _native.load_embree(embree_library_path())


class Accel(_native.Accel):
    """Embree BVH over a triangle mesh, queried with arrays of rays.

    Parameters
    ----------
    vertices : (V, 3) float32, C-contiguous
    indices : (F, 3) uint32, C-contiguous
    threads : default number of query threads; 0 means every core this process may use.
    watertight : Embree's robust build (default): no ray slips between triangles that share an edge, and hits
        are embreex's exactly.  False builds without it: closest hits are about 1.5x as fast on bounce rays (on
        x86, Embree's calls run with denormals flushed to zero), but a ray aimed within rounding of a shared edge
        can pass through it -- of rays aimed at the edges of the shipped scenes, 0.3-7% more miss than with the
        watertight build (see docs/performance.md).  Hit distances differ from the watertight ones by up to
        about 2e-5 relative.

    Rays are given as (3, N) arrays of origins and directions (float32 or
    float64, any strides) and per-ray ``tmin``/``tmax`` (scalars or (N,)
    arrays).  Queries release the GIL and run on ``threads`` threads in
    16-wide packets.
    """

    def __init__(self, vertices: np.ndarray, indices: np.ndarray, *, threads: int = 0, watertight: bool = True) -> None:
        _ensure_embree()
        super().__init__(vertices, indices, threads=threads, watertight=watertight)

    def intersect(self, origins, directions, tmin=0.0, tmax=np.inf, *, threads: int = 0,
                  normals: bool = True) -> Hits:
        """Closest hit of every ray; see :class:`Hits`."""
        return Hits(*super().intersect(origins, directions, tmin, tmax, threads=threads, normals=normals))

    def occluded(self, origins, directions, tmin=0.0, tmax=np.inf, *, threads: int = 0) -> np.ndarray:
        """Boolean (N,) array: True where a triangle lies on the ray within [tmin, tmax]."""
        return super().occluded(origins, directions, tmin, tmax, threads=threads)

    def occluded_between(self, a: np.ndarray, n_a: np.ndarray, eps_a: np.ndarray, b: np.ndarray, n_b: np.ndarray,
                         eps_b: np.ndarray, lanes: np.ndarray | None = None, b_lanes: np.ndarray | None = None, *,
                         threads: int = 0) -> np.ndarray:
        """Boolean array: True where a triangle lies between surface points ``a`` and ``b`` (3, N) float32 with unit
        normals ``n_*`` and error bounds ``eps_*`` (N,) float32, along the ray
        :func:`pathspace.vecmath.shadow_ray` makes (built in C, bit for bit, with the points gathered there) from
        ``RAY_TMIN``.  ``lanes``: int64 indices of the segments to test, (M,) (default: all N); ``b_lanes``: int64
        indices (M,) of their ends in ``b``, ``n_b`` and ``eps_b``, which may then have another width than ``a``'s
        (default: the same lanes)."""
        arrays = (np.ascontiguousarray(x) for x in (a, n_a, eps_a, b, n_b, eps_b))
        lanes, b_lanes = (None if x is None else np.ascontiguousarray(np.asarray(x).astype(np.int64, casting="safe",
                                                                                         copy=False))
                          for x in (lanes, b_lanes))
        return super().occluded_between(*arrays, lanes, b_lanes, threads=threads)
