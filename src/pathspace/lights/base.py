"""The interface every light model implements, and what the models share.

A *light model* (one module per kind: area, point, spot, directional,
environment) is a frozen dataclass holding one light's scene parameters --
parsed and validated by the model itself (:meth:`Light.from_fields`) -- plus
static methods that work on *lanes* that all use lights of that kind, given
the kind's parameter tables (:meth:`Light.tables`, built once per scene)
and ``idx``, each lane's light within the kind.  The five verbs, after
pbrt-v4's light interface (SampleLi / PDF_Li / SampleLe / PDF_Le / L):

``sample_li(tables, idx, receivers, u, colours, measure)``
    a point or direction on the light seen from ``receivers`` (3, N), from
    two uniforms per lane: a :class:`LightSample` whose ``pdf`` is the
    solid-angle density at the receiver given the light (1 for delta lights);
``pdf_li(tables, idx, receivers, points, measure)``
    that density for points found on the light by rays (lights that rays can
    hit: area lights, and the environment for rays that escape);
``sample_le(tables, idx, u, colours, context)``
    a ray leaving the light, from four uniforms per lane
    (:class:`EmissionSample`, densities given the light);
``pdf_le(tables, idx, normal, direction, context)``
    (origin density, direction density) of emitting ``direction`` from a
    point with geometric ``normal``: per area and per solid angle for finite
    lights; for lights at infinity (pbrt's convention) the origin density is
    the density of the *direction* and the direction density is the density
    on the disk the rays start from;
``le(tables, idx, normal, direction, colours)``
    what the light sends along ``direction`` from a point with geometric
    ``normal``: radiance (area, environment; 0 behind one-sided area
    lights), intensity (point, spot); 0 for directional lights.

Class attributes: ``kind`` (the name in scene files), ``delta`` (no ray can
hit it: point, spot, directional), ``infinite`` (it lies at infinity:
directional, environment), ``hit_by_escaping_rays`` (rays leaving the scene
see it: the environment).  :class:`pathspace.lights.LightSet` selects a
light among all of a scene's and dispatches lanes to their kinds; adding a
kind is one module and one entry in ``pathspace.lights.LIGHTS``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..vecmath import orthonormal_basis

__all__ = ["EmissionSample", "Light", "LightContext", "LightSample", "disk_origins"]


@dataclass
class LightSample:
    """One light sample per receiver (N lanes).

    ``wi`` (3, N) float32 unit, receiver -> light; ``distance`` (N,) float32,
    inf toward lights at infinity; ``point`` (3, N) float32 on the light
    (finite lights); ``normal`` (3, N) float32 light surface normal (area
    lights; else zero); ``value`` (C, N) float64: radiance, I / d^2 or
    irradiance, the factor that multiplies f |cos| / pdf; ``facing`` (N,):
    the light emits toward the receiver (one-sided area lights); ``pdf``
    (N,) float64 solid-angle density (with the selection pmf once the
    LightSet has chosen the light; for delta lights the pmf alone);
    ``delta`` (N,); ``epsilon`` (N,) float32 error bound of the light's
    surface (area lights; else 0); ``entity`` (N,) int64 the sampled light
    (set by the LightSet).
    """

    wi: np.ndarray
    distance: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    value: np.ndarray
    facing: np.ndarray
    pdf: np.ndarray
    delta: np.ndarray
    epsilon: np.ndarray
    entity: np.ndarray | None = None


@dataclass
class EmissionSample:
    """A ray leaving a light (for light subpaths), one per lane.

    ``pdf_pos``: density of the origin (with the selection pmf once the
    LightSet has chosen the light) -- in area measure for area lights, 1
    (a delta) for point and spot lights, for lights at infinity the density
    on the disk the rays start from.  ``pdf_dir``: solid-angle density of the
    direction (1 for a directional light's delta direction).  ``value``:
    radiance (area, environment), intensity (point, spot) or irradiance
    (directional) carried by the ray.  The ray leaves ``point`` along
    ``direction`` (moved off an area light's surface by its error bound
    ``epsilon``, see :func:`pathspace.vecmath.offset_origin`; else 0); for
    lights at infinity ``point`` lies on a disk outside the scene and
    ``normal`` is the direction; point and spot lights have a zero
    ``normal``.  ``cos_light``: |cos| at the origin (area lights), else 1.
    """

    point: np.ndarray
    epsilon: np.ndarray
    normal: np.ndarray
    direction: np.ndarray
    value: np.ndarray
    pdf_pos: np.ndarray
    pdf_dir: np.ndarray
    cos_light: np.ndarray
    entity: np.ndarray | None = None
    infinite: np.ndarray | None = None


@dataclass(frozen=True)
class LightContext:
    """What light models read from the scene: the mesh (area lights), the radius of a sphere holding
    all geometry (the power of lights at infinity is what crosses it), and a disk center and radius
    outside which rays from lights at infinity start (a sphere holding the geometry and a thin lens)."""

    mesh: object
    scene_radius: float
    disk_center: np.ndarray
    disk_radius: float


class Light:
    """Base of the light models; see the module docstring for the interface."""

    kind: ClassVar[str]
    delta: ClassVar[bool] = False
    infinite: ClassVar[bool] = False
    hit_by_escaping_rays: ClassVar[bool] = False

    @staticmethod
    def pdf_li(tables, idx: np.ndarray, receivers: np.ndarray, points: np.ndarray, measure: str) -> np.ndarray:
        """Lights no ray can hit have no density of being found."""
        return np.zeros(idx.size)

    def translated(self, offset: np.ndarray) -> "Light":
        """The light with every position moved by ``offset`` (3,) (into the scene's render space); lights
        without a position of their own (area lights live on the mesh, lights at infinity) are unchanged."""
        return self


def disk_origins(context: LightContext, d: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Origins (3, N) of rays along unit directions ``d`` (3, N) that cover the scene: uniform points, from
    uniforms ``u`` (2, N), on the disk of radius ``context.disk_radius`` facing ``d``, centred a radius
    before the disk center (density 1 / (pi r^2))."""
    radius = context.disk_radius
    s, t = orthonormal_basis(d.astype(np.float64))
    r = radius * np.sqrt(u[0])
    phi = 2 * np.pi * u[1]
    return context.disk_center[:, None] - d * radius + s * (r * np.cos(phi)) + t * (r * np.sin(phi))
