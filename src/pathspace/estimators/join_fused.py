"""Bidirectional path tracing's joins of light and camera vertices in one C pass.

:func:`~pathspace.estimators.connections.joins` forms every strategy with
s, t >= 2: for each pair of vertices, both BSDFs toward each other, the
geometry term, the contribution and four densities of the MIS ratio chain,
three dozen array operations over the pairs' gathered fields.  For the
scenes and settings most BDPT renders use, ``ext/join.c`` does it per pair
in one pass, bit for bit as the NumPy code does (which stays the reference
and serves every other case):

- RGB rendering;
- diffuse, mirror and smooth dielectric materials (those of
  :data:`pathspace.estimators.pt_fused.MODELS`; the vertices joined are the
  non-specular ones, so diffuse);
- connections with MIS densities (BDPT; light tracing makes no joins).

The lights and the camera play no part in a join.  :func:`join_kernel` says
whether a scene and settings are served, and why not.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import _native
from ..spectra import RGBColours
from .pt_fused import diffuse_tables, unserved

__all__ = ["JoinKernel", "JoinResult", "join_kernel"]


@dataclass
class JoinResult:
    """What ``ext/join.c`` gives for K pairs (y, z): the unweighted contributions ``value`` (3, K) before the
    shadow ray, and the densities of :class:`~pathspace.mis.Connections` the join changes (K,) each."""

    value: np.ndarray
    qs_rev: np.ndarray
    qs_minus_rev: np.ndarray
    pt_rev: np.ndarray
    pt_minus_rev: np.ndarray


@dataclass(frozen=True, eq=False)
class JoinKernel:
    """The tables ``ext/join.c`` reads for one scene and one diffuse sampling technique: which materials are
    diffuse, and their reflectance."""

    diffuse: np.ndarray       # (M,) bool
    reflectance: np.ndarray   # (3, M) float64
    technique: int            # index in DIFFUSE_SAMPLING

    def __call__(self, light, eye, y: np.ndarray, z: np.ndarray) -> JoinResult:
        """The joins of the vertices ``y`` (int64 indices) of the subpaths ``light`` to the vertices ``z`` of the
        subpaths ``eye``, pair by pair."""
        fields = [np.ascontiguousarray(getattr(side, name)) for side in (light, eye)
                  for name in ("p", "n", "wo", "beta", "material", "q", "q_rev", "g_prev")]
        return JoinResult(*_native.join_vertices(*fields, np.ascontiguousarray(y, np.int64),
                                                 np.ascontiguousarray(z, np.int64), self.diffuse, self.reflectance,
                                                 self.technique))


def join_kernel(scene, colours, densities: bool, options: dict, kernel: str) -> tuple[JoinKernel | None, str]:
    """(the kernel, "") if a bidirectional estimator with ``kernel`` ("fused" or "numpy") can join its light and
    camera vertices on ``scene`` through ``ext/join.c``, rendering with ``colours``, with or without MIS
    ``densities`` and with the material ``options`` (``diffuse_sampling``); else (None, why not)."""
    reason = unserved(scene, colours is RGBColours, kernel)
    if reason:
        return None, reason
    if not densities:
        return None, "connections without MIS densities"
    return JoinKernel(*diffuse_tables(scene.materials, options)), ""
