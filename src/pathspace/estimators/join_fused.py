"""Bidirectional path tracing's joins in one C pass: light and camera vertices, and camera vertices and light samples.

:func:`~pathspace.estimators.connections.joins` forms every strategy with
s, t >= 2: for each pair of vertices, both BSDFs toward each other, the
geometry term, the contribution and four densities of the MIS ratio chain,
three dozen array operations over the pairs' gathered fields.
:func:`~pathspace.estimators.connections.light_samples` forms the strategies
with s = 1: a fresh point on a light for each camera vertex, the BSDF toward
it, the contribution and the densities, as many operations again.  For the
scenes and settings most BDPT renders use, ``ext/join.c`` does each per pair
in one pass, bit for bit as the NumPy code does (which stays the reference
and serves every other case):

- RGB rendering;
- diffuse, mirror and smooth dielectric materials (those of
  :data:`pathspace.estimators.pt_fused.MODELS`; the vertices joined are the
  non-specular ones, so diffuse);
- connections with MIS densities (BDPT; light tracing makes no joins);
- for the light samples: area lights alone (points sampled by area, lights
  chosen by power, as ``light_samples`` does).

The camera plays no part in a join.  :func:`join_kernel` and
:func:`light_sample_kernel` say whether a scene and settings are served, and
why not.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import _native
from ..lights import AreaLight
from ..spectra import RGBColours
from .pt_fused import diffuse_tables, emitter_radiance, unserved
from .subpaths import LIGHT_SELECTION

__all__ = ["JoinKernel", "JoinResult", "LightJoin", "LightSampleKernel", "join_kernel", "light_sample_kernel"]


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


@dataclass
class LightJoin:
    """What ``ext/join.c`` gives for K camera vertices joined to fresh light samples: the unweighted contributions
    ``value`` (3, K) before the shadow ray; the emitting triangle (the light ``entity``), ``point``, unit
    ``normal`` (3, K) float32 and ray offset ``epsilon`` of each sample; and the densities of
    :class:`~pathspace.mis.Connections` the join changes (K,) each."""

    value: np.ndarray
    entity: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    epsilon: np.ndarray
    qs_fwd: np.ndarray
    qs_rev: np.ndarray
    pt_rev: np.ndarray
    pt_minus_rev: np.ndarray


@dataclass(frozen=True, eq=False)
class LightSampleKernel:
    """The tables ``ext/join.c`` reads to join camera vertices to light samples: the materials' (as
    :class:`JoinKernel`) and the emitting triangles' (table, area, two_sided, the selection's cdf and pmf, and
    RGB radiance (3, E))."""

    diffuse: np.ndarray       # (M,) bool
    reflectance: np.ndarray   # (3, M) float64
    technique: int            # index in DIFFUSE_SAMPLING
    lights: tuple

    def __call__(self, eye, z: np.ndarray) -> LightJoin:
        """The vertices ``z`` (int64 indices) of the subpaths ``eye`` joined to light samples drawn from their
        first three connection numbers ``eye.u``."""
        fields = [np.ascontiguousarray(getattr(eye, name)) for name in ("p", "n", "wo", "beta", "material", "q",
                                                                        "q_rev", "g_prev", "u")]
        return LightJoin(*_native.join_light_samples(*fields, np.ascontiguousarray(z, np.int64), self.diffuse,
                                                     self.reflectance, *self.lights, self.technique))


def light_sample_kernel(scene, colours, options: dict, kernel: str) -> tuple[LightSampleKernel | None, str]:
    """(the kernel, "") if BDPT with ``kernel`` ("fused" or "numpy") can join its camera vertices to light
    samples on ``scene`` through ``ext/join.c``, rendering with ``colours`` and with the material ``options``
    (``diffuse_sampling``); else (None, why not)."""
    reason = unserved(scene, colours is RGBColours, kernel)
    if reason:
        return None, reason
    lights = scene.lights
    if lights.models != [AreaLight]:
        return None, "lights other than area lights"
    area = lights.area
    tables = (area.table, area.area, area.two_sided, np.ascontiguousarray(lights.cdf(LIGHT_SELECTION)),
              np.ascontiguousarray(lights.pmf(LIGHT_SELECTION)), emitter_radiance(lights))
    return LightSampleKernel(*diffuse_tables(scene.materials, options), tables), ""
