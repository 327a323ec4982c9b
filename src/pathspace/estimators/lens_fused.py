"""The light tracer's connections to the camera in one C pass.

:func:`~pathspace.estimators.connections.lens_samples` joins light
vertices to the lens: the camera's geometry, what each vertex sends toward
it (a BSDF or an emitter, :func:`~pathspace.estimators.connections._toward_lens`)
and the contribution, a few dozen array operations over the vertices'
gathered fields.  For the scenes and settings most light-tracing renders
use, ``ext/lens_connect.c`` does it per vertex in one pass, bit for bit as
the NumPy code does (which stays the reference and serves every other case):

- RGB rendering, contributions without MIS densities (light tracing);
- a pinhole camera;
- area lights alone;
- diffuse, mirror and smooth dielectric materials (those of
  :data:`pathspace.estimators.pt_fused.MODELS`; the vertices joined are the
  non-specular ones, so diffuse).

Area lights are the first entities of a scene's lights, so a vertex on a
light indexes the emitting triangles' tables by its entity.

:func:`lens_kernel` says whether a scene and settings are served, and why not.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import _native
from ..bsdfs import Diffuse
from ..camera import PinholeCamera
from ..lights import AreaLight
from ..spectra import RGBColours
from .pt_fused import emitter_radiance, material_rgb, unserved_material

__all__ = ["LensKernel", "lens_kernel"]


@dataclass(frozen=True, eq=False)
class LensKernel:
    """The tables ``ext/lens_connect.c`` reads for one scene: which materials are diffuse and their
    reflectance, the emitting triangles' radiance and sidedness, and the pinhole camera."""

    diffuse: np.ndarray       # (M,) bool
    reflectance: np.ndarray   # (3, M) float64
    radiance: np.ndarray      # (3, E) float64, per emitting triangle
    two_sided: np.ndarray     # (E,) bool
    camera: PinholeCamera

    def __call__(self, light, chosen: np.ndarray, on_light: np.ndarray):
        """For the vertices ``chosen`` (int64 indices) of the subpaths ``light``, those on lights where
        ``on_light``: (beta times what each sends toward the pinhole (3, K), the pinhole's solid-angle density
        at it (K,), its raster position (2, K), whether that is on the film (K,), the cosine at the lens (K,))."""
        camera = self.camera
        vertices = (np.ascontiguousarray(a) for a in (light.p, light.n, light.wo, light.beta, light.material,
                                                      light.entity))
        return _native.lens_connect(*vertices, np.ascontiguousarray(chosen, np.int64), np.ascontiguousarray(on_light),
                                    self.diffuse, self.reflectance, self.radiance, self.two_sided, camera.position,
                                    camera.forward, camera.right, camera.image_up, camera.tan_half[0],
                                    camera.tan_half[1], camera.width, camera.height, camera.lens_area)


def lens_kernel(scene, colours, densities: bool, kernel: str) -> tuple[LensKernel | None, str]:
    """(the kernel, "") if a light tracer with ``kernel`` ("fused" or "numpy") can join its vertices to the
    camera of ``scene`` through ``ext/lens_connect.c``, rendering with ``colours`` and with or without MIS
    ``densities``; else (None, why not)."""
    if kernel != "fused":
        return None, "kernel='numpy'"
    if colours is not RGBColours:
        return None, "spectral rendering"
    if densities:
        return None, "connections with MIS densities"
    if type(scene.camera) is not PinholeCamera:
        return None, "a camera other than a pinhole"
    if scene.lights.models != [AreaLight]:
        return None, "lights other than area lights"
    table = scene.materials
    reason = unserved_material(table)
    if reason:
        return None, reason
    diffuse = np.array([type(m) is Diffuse for m in table.materials], dtype=bool)
    return LensKernel(diffuse, material_rgb(table)[0], emitter_radiance(scene.lights),
                      np.ascontiguousarray(scene.lights.area.two_sided), scene.camera), ""
