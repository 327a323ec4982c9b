"""Light vertices joined to the camera (light tracing, BDPT's t = 1) in one C pass.

:func:`~pathspace.estimators.connections.lens_samples` joins light
vertices to the lens: the camera's geometry, what each vertex sends toward
it (a BSDF or an emitter, :func:`~pathspace.estimators.connections._toward_lens`),
the contribution and, for BDPT, the MIS densities, a few dozen array
operations over the vertices' gathered fields.  For the scenes and settings
most renders use, ``ext/lens_connect.c`` does it per vertex in one pass, bit for bit as
the NumPy code does (which stays the reference and serves every other case):

- RGB rendering;
- a pinhole camera;
- area lights alone;
- diffuse, mirror and smooth dielectric materials (those of
  :data:`pathspace.estimators.pt_fused.MODELS`; the vertices joined are the
  non-specular ones, so diffuse).

With MIS densities (BDPT), the kernel also gives those the connection
changes (see :class:`LensJoin`).  Area lights are the first
entities of a scene's lights, so a vertex on a light indexes the emitting
triangles' tables by its entity.

:func:`lens_kernel` says whether a scene and settings are served, and why not.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import _native
from ..camera import PinholeCamera
from ..lights import AreaLight
from ..spectra import RGBColours
from .pt_fused import diffuse_tables, emitter_radiance, unserved

__all__ = ["LensJoin", "LensKernel", "lens_kernel"]


@dataclass
class LensJoin:
    """What ``ext/lens_connect.c`` gives for K light vertices joined to the pinhole: the contribution ``value``
    (3, K) -- beta times what each sends toward it, times the camera's importance over the pinhole's density, 0
    off the film -- and its ``raster`` position (2, K); with densities (else None), the MIS densities ``pt_rev``,
    ``qs_minus_rev`` and ``qs_rev`` (see :class:`~pathspace.mis.Connections`)."""

    value: np.ndarray
    raster: np.ndarray
    pt_rev: np.ndarray | None = None
    qs_minus_rev: np.ndarray | None = None
    qs_rev: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class LensKernel:
    """The tables ``ext/lens_connect.c`` reads for one scene: which materials are diffuse and their
    reflectance, the emitting triangles' radiance and sidedness, the pinhole camera and the diffuse sampling
    technique."""

    diffuse: np.ndarray       # (M,) bool
    reflectance: np.ndarray   # (3, M) float64
    radiance: np.ndarray      # (3, E) float64, per emitting triangle
    two_sided: np.ndarray     # (E,) bool
    camera: PinholeCamera
    technique: int            # index in DIFFUSE_SAMPLING

    def __call__(self, light, chosen: np.ndarray, on_light: np.ndarray, densities: bool) -> LensJoin:
        """The vertices ``chosen`` (int64 indices) of the subpaths ``light``, those on lights where ``on_light``,
        joined to the pinhole, with the MIS ``densities`` or without."""
        camera = self.camera
        vertices = (np.ascontiguousarray(a) for a in (light.p, light.n, light.wo, light.beta, light.material,
                                                      light.entity))
        densities = ((np.ascontiguousarray(a) for a in (light.q, light.q_rev, light.g_prev)) if densities
                     else (None, None, None))
        return LensJoin(*_native.lens_connect(
            *vertices, np.ascontiguousarray(chosen, np.int64), np.ascontiguousarray(on_light), self.diffuse,
            self.reflectance, self.radiance, self.two_sided, camera.position, camera.forward, camera.right,
            camera.image_up, camera.tan_half[0], camera.tan_half[1], camera.width, camera.height, camera.lens_area,
            camera.image_area * camera.lens_area, self.technique, *densities))


def lens_kernel(scene, colours, options: dict, kernel: str) -> tuple[LensKernel | None, str]:
    """(the kernel, "") if a bidirectional estimator with ``kernel`` ("fused" or "numpy") can join its light
    vertices to the camera of ``scene`` through ``ext/lens_connect.c``, rendering with ``colours`` and with the
    material ``options`` (``diffuse_sampling``); else (None, why not)."""
    reason = unserved(scene, colours is RGBColours, kernel)
    if reason:
        return None, reason
    if type(scene.camera) is not PinholeCamera:
        return None, "a camera other than a pinhole"
    if scene.lights.models != [AreaLight]:
        return None, "lights other than area lights"
    diffuse, reflectance, technique = diffuse_tables(scene.materials, options)
    return LensKernel(diffuse, reflectance, emitter_radiance(scene.lights),
                      np.ascontiguousarray(scene.lights.area.two_sided), scene.camera, technique), ""
