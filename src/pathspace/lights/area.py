"""Area lights: the triangles of a shape, emitting constant radiance.

Each emitting triangle has the constant radiance Le of its light on the side
of its geometric normal (one-sided, the default) or on both sides.  Every
emitting triangle is a light of its own for light selection.  Given a
triangle, a point is sampled either uniformly by area, with solid-angle
density at a receiver

    p_sa = (1 / area) * dist^2 / |cos theta_light|          (Veach 1997, eq. 8.10)

or uniformly over the solid angle the triangle subtends (Arvo 1995), density
1 / Omega, where that is well conditioned (as in pbrt-v4: 3e-4 < Omega <
6.22 sr; outside it, area sampling is used, and the densities say so).
Emitted rays leave a uniform point in a cosine-weighted direction (either
side of two-sided lights, chosen with probability 1/2).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from .. import _native, warp
from ..spectra import Colour, ColourTable, check_emission
from ..vecmath import dot
from ..warp import square_to_uniform_triangle
from .base import EmissionSample, Light, LightContext, LightSample
from .spherical_triangle import sample_spherical_triangle, solid_angle

if TYPE_CHECKING:
    from ..fields import Fields
    from ..scene.mesh import TriangleMesh

__all__ = ["AreaLight", "AreaTables", "MEASURES"]

MEASURES = ("area", "solid_angle")
SOLID_ANGLE_RANGE = (3e-4, 6.22)


@dataclass(frozen=True, eq=False)
class AreaLight(Light):
    """The triangles ``triangles`` (indices into the scene mesh) of a shape, emitting ``radiance``
    (W sr^-1 m^-2, RGB or a spectrum) on the side of their normals, or on both if ``two_sided``."""

    radiance: Colour
    two_sided: bool = False
    triangles: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    kind = "area"

    def __post_init__(self) -> None:
        object.__setattr__(self, "radiance", check_emission(self.radiance, "radiance"))
        object.__setattr__(self, "triangles", np.asarray(self.triangles, dtype=np.int64).reshape(-1))

    @classmethod
    def from_fields(cls, fields: "Fields") -> "AreaLight":
        """An ``emitter`` table of a shape: ``radiance``, ``two_sided`` (its triangles are set by the loader)."""
        radiance = fields.colour("radiance")
        two_sided = fields.boolean("two_sided", False)
        fields.finish()
        return fields.build(lambda: cls(radiance, two_sided))

    def on(self, triangles: np.ndarray) -> "AreaLight":
        """The same emitter on the given mesh triangles."""
        return replace(self, triangles=triangles)

    @staticmethod
    def tables(lights: list["AreaLight"], context: LightContext) -> "AreaTables":
        """Per-triangle tables of all area lights of a scene."""
        triangles = [light.triangles for light in lights]
        light_of = [np.full(t.size, j) for j, t in enumerate(triangles)]
        return AreaTables(context.mesh, np.concatenate(triangles or [np.zeros(0, np.int64)]),
                          np.concatenate(light_of or [np.zeros(0, np.int64)]),
                          ColourTable([light.radiance for light in lights], "illuminant"),
                          np.array([light.two_sided for light in lights], dtype=bool))

    @staticmethod
    def power(tables: "AreaTables", context: LightContext) -> np.ndarray:
        """Emitted power of every emitting triangle."""
        return tables.power

    @staticmethod
    def sample_li(tables: "AreaTables", idx, receivers, u, colours, measure: str) -> LightSample:
        """Points on the triangles ``idx`` for receivers (3, N), by area or by solid angle."""
        point, normal, wi, distance, cos_light, pdf = tables.sample(idx, receivers, u, measure)
        facing = tables.faces(idx, cos_light)
        return LightSample(wi, distance, point, normal, tables.radiance_of(idx, colours), facing, pdf,
                           np.zeros(pdf.shape, dtype=bool), tables.table[12].take(idx))

    @staticmethod
    def sample_li_selected(tables: "AreaTables", cdf: np.ndarray, pmf: np.ndarray, receivers: np.ndarray,
                           u: np.ndarray, colours) -> LightSample:
        """:meth:`sample_li` by area on emitting triangles chosen from ``cdf`` by ``u[0]`` (``pmf`` their
        probabilities; the density includes it), for receivers (3, N) float32 and uniforms u (3, N) float64,
        in one C pass (``ext/lights.c``)."""
        entity, point, normal, wi, distance, facing, pdf, epsilon = _native.area_light_sample(
            tables.table, tables.area, tables.two_sided, cdf, pmf, np.ascontiguousarray(u[:3]),
            np.ascontiguousarray(receivers))
        return LightSample(wi, distance, point, normal, tables.radiance_of(entity, colours), facing, pdf,
                           np.zeros(pdf.shape, dtype=bool), epsilon, entity)

    @staticmethod
    def pdf_li(tables: "AreaTables", idx, receivers, points, measure: str) -> np.ndarray:
        """Solid-angle density of finding ``points`` on triangles ``idx`` by :meth:`sample_li`."""
        return tables.pdf_sa(idx, receivers, points, measure)

    @staticmethod
    def sample_le(tables: "AreaTables", idx, u, colours, context: LightContext) -> EmissionSample:
        """A uniform point and a cosine-weighted direction (on either side of two-sided lights)."""
        p, n, epsilon = tables.uniform_points(idx, u[0:2])
        two = tables.two_sided.take(idx)
        d = tables.emitted_directions(idx, n, u[2:4])
        cos = np.abs(dot(n, d)).astype(np.float64)
        return EmissionSample(point=p, epsilon=epsilon, normal=n,
                              direction=d, value=tables.radiance_of(idx, colours),
                              pdf_pos=1.0 / tables.area.take(idx), pdf_dir=cos * warp.INV_PI * np.where(two, 0.5, 1.0),
                              cos_light=cos)

    @staticmethod
    def pdf_le(tables: "AreaTables", idx, normal, direction, context: LightContext):
        """(1 / area, cosine-weighted density of ``direction``)."""
        cos = dot(normal, direction).astype(np.float64)
        two = tables.two_sided.take(idx)
        return 1.0 / tables.area.take(idx), np.where(two, np.abs(cos) * 0.5, np.maximum(cos, 0.0)) * warp.INV_PI

    @staticmethod
    def le(tables: "AreaTables", idx, normal, direction, colours) -> np.ndarray:
        """Radiance toward ``direction`` (0 behind one-sided lights)."""
        return tables.emitted(idx, dot(normal, direction), colours)


class AreaTables:
    """The emitting triangles of a scene and their per-triangle tables.

    ``triangles`` (E,) mesh indices of the emitting triangles; ``light_of``
    (E,) the area light each belongs to; ``radiance`` a ColourTable of the
    lights' radiance; ``two_sided`` (E,); ``area`` (E,); ``table`` the
    mesh's geometry rows of the emitting triangles; ``emitter_of_triangle``
    (F,) the emitting-triangle index of every mesh triangle, or -1.
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

    def emitted_directions(self, emitter: np.ndarray, normal: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Directions (3, N) leaving points with unit ``normal`` (3, N) on triangles ``emitter``, cosine-weighted
        about the normal, on a side chosen by ``u[0]`` for two-sided lights (the density
        :meth:`AreaLight.pdf_le` gives); ``u`` (2, N)."""
        two = self.two_sided.take(emitter)
        side = np.where(two & (u[0] < 0.5), np.float32(-1), np.float32(1))
        u_side = np.where(two, (u[0] * 2) % 1.0, u[0])  # reused after choosing a side
        return warp.square_to_cosine_about(normal * side, np.stack((u_side, u[1])))

    def uniform_points(self, emitter: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Points uniform in area on triangles ``emitter`` (density 1 / area): (points, unit normals, ray offsets),
        float32."""
        b1, b2 = square_to_uniform_triangle(u)
        return self.mesh.hit_geometry(self.triangles.take(emitter), b1, b2)

    def sample(self, emitter: np.ndarray, receivers: np.ndarray, u: np.ndarray, measure: str):
        """Points on triangles ``emitter`` for receivers (3, N): (point, normal, wi, distance, cos_light, pdf_sa).

        ``pdf_sa`` is the solid-angle density at the receiver given the triangle.
        """
        point, normal, _ = self.uniform_points(emitter, u)
        if measure == "solid_angle":
            point, omega = self._solid_angle_points(np.take(self.table, emitter, axis=1), receivers, point, u)
        wi = point - receivers
        dist2 = dot(wi, wi)
        distance = np.sqrt(dist2)
        wi = np.divide(wi, distance, out=np.zeros_like(wi), where=distance > 0)  # a receiver on the light: no sample
        cos_light = -dot(normal, wi)
        with np.errstate(divide="ignore", invalid="ignore"):
            pdf = dist2.astype(np.float64) / (self.area.take(emitter) * np.abs(cos_light).astype(np.float64))
        pdf = np.where(distance > 0, pdf, 0.0)
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
        """Solid-angle density with which :meth:`sample` picks ``points`` on triangles ``emitter``."""
        rows = np.take(self.table, emitter, axis=1)
        to_point = points - receivers
        dist2 = dot(to_point, to_point).astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            cos_light = np.abs(dot(rows[9:12], to_point)).astype(np.float64) / np.sqrt(dist2)
            # a point on the receiver itself (closer than float32 tells apart): no light sample lands there
            pdf = np.where(dist2 > 0, dist2 / (self.area.take(emitter) * cos_light), 0.0)
        if measure == "solid_angle":
            p0 = rows[0:3].astype(np.float64)
            omega = solid_angle(p0, p0 + rows[3:6], p0 + rows[6:9], receivers.astype(np.float64))
            with np.errstate(divide="ignore"):
                pdf = np.where(_spherical(omega), 1.0 / omega, pdf)
        return pdf

    def radiance_of(self, emitter: np.ndarray, colours) -> np.ndarray:
        """Radiance (C, N) of emitting triangles ``emitter`` (on their emitting sides)."""
        return colours.lookup(self.radiance, self.light_of.take(emitter))

    def faces(self, emitter: np.ndarray, cos_light: np.ndarray) -> np.ndarray:
        """Whether triangles ``emitter`` emit toward viewers at dot(n, w_view) = ``cos_light`` (N,): two-sided
        lights everywhere, one-sided ones in front."""
        return self.two_sided.take(emitter) | (cos_light > 0)

    def emitted(self, emitter: np.ndarray, cos_light: np.ndarray, colours) -> np.ndarray:
        """Radiance (C, N) leaving triangles ``emitter`` toward viewers at dot(n, w_view) = ``cos_light``."""
        return self.radiance_of(emitter, colours) * self.faces(emitter, cos_light)


def _spherical(omega: np.ndarray) -> np.ndarray:
    return (omega > SOLID_ANGLE_RANGE[0]) & (omega < SOLID_ANGLE_RANGE[1])
