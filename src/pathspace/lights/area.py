"""Area lights: emitting triangles of the scene mesh.

Each emitting triangle has the constant radiance Le of its light (an emitting
shape) on the side of its geometric normal (one-sided, the default) or on
both sides.  Given a triangle, a point
is sampled either uniformly by area, with solid-angle density at a receiver

    p_sa = (1 / area) * dist^2 / |cos theta_light|          (Veach 1997, eq. 8.10)

or uniformly over the solid angle the triangle subtends (Arvo 1995), density
1 / Omega, where that is well conditioned (as in pbrt-v4: 3e-4 < Omega <
6.22 sr; outside it, area sampling is used, and the densities say so).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..spectra import ColourTable
from ..vecmath import dot
from ..warp import square_to_uniform_triangle
from .spherical_triangle import sample_spherical_triangle, solid_angle

if TYPE_CHECKING:
    from ..scene.mesh import TriangleMesh

__all__ = ["AreaLights", "MEASURES"]

MEASURES = ("area", "solid_angle")
SOLID_ANGLE_RANGE = (3e-4, 6.22)


class AreaLights:
    """The emitting triangles of a scene.

    Parameters
    ----------
    mesh : the scene mesh
    triangles : (E,) indices of emitting triangles
    light_of : (E,) index of the light (emitting shape) each triangle belongs to
    radiance : the radiance of each light (W sr^-1 m^-2, RGB or spectral), a ColourTable of "illuminant" kind
    two_sided : (L,) whether each light emits on both sides
    """

    def __init__(self, mesh: "TriangleMesh", triangles: np.ndarray, light_of: np.ndarray, radiance: ColourTable,
                 two_sided: np.ndarray) -> None:
        self.mesh = mesh
        self.triangles = np.asarray(triangles, dtype=np.int64)
        self.light_of = np.asarray(light_of, dtype=np.int64)
        self.radiance = radiance
        self.two_sided = np.asarray(two_sided, dtype=bool).take(self.light_of)
        self.area = mesh.area[self.triangles]
        self.emitter_of_triangle = np.full(mesh.triangle_count, -1, dtype=np.int64)
        self.emitter_of_triangle[self.triangles] = np.arange(self.triangles.size)
        self.table = np.take(mesh.table, self.triangles, axis=1)  # geometry rows of the emitting triangles
        # Emitted power of each triangle: pi * area * mean RGB radiance per emitting side.
        self.power = np.pi * self.area * radiance.mean().take(self.light_of) * np.where(self.two_sided, 2.0, 1.0)

    @property
    def count(self) -> int:
        """Number of emitting triangles."""
        return int(self.triangles.size)

    @property
    def light_count(self) -> int:
        """Number of emitting shapes."""
        return int(np.unique(self.light_of).size)

    def uniform_points(self, emitter: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points uniform in area on triangles ``emitter`` (density 1 / area): (their geometry rows, points)."""
        rows = np.take(self.table, emitter, axis=1)
        b1, b2 = square_to_uniform_triangle(u)
        return rows, rows[0:3] + rows[3:6] * b1.astype(np.float32) + rows[6:9] * b2.astype(np.float32)

    def sample(self, emitter: np.ndarray, receivers: np.ndarray, u: np.ndarray, measure: str):
        """Points on triangles ``emitter`` for receivers (3, N): (point, normal, wi, distance, cos_light, pdf_sa).

        ``pdf_sa`` is the solid-angle density at the receiver given the triangle
        (the selection probability is not included).
        """
        rows, point = self.uniform_points(emitter, u)
        normal = rows[9:12]
        if measure == "solid_angle":
            point, omega = self._solid_angle_points(rows, receivers, point, u)
        wi = point - receivers
        dist2 = dot(wi, wi)
        distance = np.sqrt(dist2)
        wi /= distance
        cos_light = -dot(normal, wi)
        with np.errstate(divide="ignore", invalid="ignore"):
            pdf = dist2.astype(np.float64) / (self.area.take(emitter) * np.abs(cos_light).astype(np.float64))
        if measure == "solid_angle":
            with np.errstate(divide="ignore"):
                pdf = np.where(_spherical(omega), 1.0 / omega, pdf)
        return point, normal, wi, distance, cos_light, pdf

    def _solid_angle_points(self, rows, receivers, area_points, u):
        """Replace area samples by solid-angle samples where the triangle is well conditioned."""
        p0 = rows[0:3].astype(np.float64)
        p1 = p0 + rows[3:6]
        p2 = p0 + rows[6:9]
        ref = receivers.astype(np.float64)
        direction, omega = sample_spherical_triangle(p0, p1, p2, ref, u)
        # The sampled direction meets the triangle's plane at the sampled point.
        normal = rows[9:12].astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = dot(normal, p0 - ref) / dot(normal, direction)
        use = _spherical(omega) & np.isfinite(t) & (t > 0)
        point = np.where(use, (ref + direction * t).astype(np.float32), area_points)
        return point, np.where(use, omega, 0.0)

    def pdf_sa(self, emitter: np.ndarray, receivers: np.ndarray, points: np.ndarray, measure: str) -> np.ndarray:
        """Solid-angle density with which :meth:`sample` picks ``points`` on triangles ``emitter`` (given the triangle)."""
        rows = np.take(self.table, emitter, axis=1)
        to_point = points - receivers
        dist2 = dot(to_point, to_point).astype(np.float64)
        cos_light = np.abs(dot(rows[9:12], to_point)).astype(np.float64) / np.sqrt(dist2)
        with np.errstate(divide="ignore", invalid="ignore"):
            pdf = dist2 / (self.area.take(emitter) * cos_light)
        if measure == "solid_angle":
            p0 = rows[0:3].astype(np.float64)
            omega = solid_angle(p0, p0 + rows[3:6], p0 + rows[6:9], receivers.astype(np.float64))
            with np.errstate(divide="ignore"):
                pdf = np.where(_spherical(omega), 1.0 / omega, pdf)
        return pdf

    def radiance_of(self, emitter: np.ndarray, colours) -> np.ndarray:
        """Radiance (C, N) of emitting triangles ``emitter`` (on their emitting sides)."""
        return colours.lookup(self.radiance, self.light_of.take(emitter))

    def emitted(self, emitter: np.ndarray, cos_light: np.ndarray, colours) -> np.ndarray:
        """Radiance (C, N) leaving triangles ``emitter`` toward viewers at dot(n, w_view) = ``cos_light``."""
        facing = self.two_sided.take(emitter) | (cos_light > 0)
        return self.radiance_of(emitter, colours) * facing


def _spherical(omega: np.ndarray) -> np.ndarray:
    return (omega > SOLID_ANGLE_RANGE[0]) & (omega < SOLID_ANGLE_RANGE[1])
