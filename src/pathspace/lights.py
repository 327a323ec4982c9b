"""Emitters: area lights on triangles, and their sampling.

An area light is a shape whose triangles emit constant radiance ``Le`` on the
side of their geometric normal (one-sided, the default) or on both sides.
Next-event estimation picks an emitting triangle with a discrete pmf (by
power or uniformly over lights, area-weighted within a light) and a point on
it uniformly by area; the pdf of that sample in solid angle at a receiver is

    p_sa = pmf(tri) / area(tri) * dist^2 / |cos theta_light|       (Veach 1997, eq. 8.10)
"""
from __future__ import annotations

import numpy as np

from .scene.mesh import TriangleMesh
from .vecmath import dot
from .warp import square_to_uniform_triangle

__all__ = ["AreaLights", "LightSample"]

SELECTION_STRATEGIES = ("power", "uniform")


class LightSample:
    """Result of :meth:`AreaLights.sample` for N receivers (unit direction wi toward the light)."""

    __slots__ = ("wi", "distance", "point", "normal", "radiance", "facing", "pdf_sa", "cos_light")

    def __init__(self, wi, distance, point, normal, radiance, facing, pdf_sa, cos_light):
        self.wi = wi                  # (3, N) float32, unit, receiver -> light
        self.distance = distance      # (N,) float32
        self.point = point            # (3, N) float32, sampled point on the light
        self.normal = normal          # (3, N) float32, unit geometric normal of the light triangle
        self.radiance = radiance      # (3, N) float64, Le of the sampled triangle
        self.facing = facing          # (N,) bool, whether it emits toward the receiver (one-sided lights)
        self.pdf_sa = pdf_sa          # (N,) float64, solid-angle pdf at the receiver (inf if degenerate)
        self.cos_light = cos_light    # (N,) float32, dot(normal, -wi)


class AreaLights:
    """The emitting triangles of a scene with a discrete pmf for choosing among them.

    Parameters
    ----------
    mesh : the scene mesh
    triangles : (E,) indices of emitting triangles
    radiance : (3, E) RGB radiance of each (W sr^-1 m^-2 per channel)
    two_sided : (E,) whether each emits on both sides
    light_of : (E,) index of the light (emitting shape) each triangle belongs to
    selection : "power" (pmf proportional to emitted power) or "uniform" (each
        light equally likely); triangles within a light are chosen by area.
    """

    def __init__(self, mesh: TriangleMesh, triangles: np.ndarray, radiance: np.ndarray, two_sided: np.ndarray,
                 light_of: np.ndarray, selection: str = "power") -> None:
        if selection not in SELECTION_STRATEGIES:
            raise ValueError(f"light selection: expected one of {SELECTION_STRATEGIES}, got {selection!r}")
        self.mesh = mesh
        self.selection = selection
        self.triangles = np.asarray(triangles, dtype=np.int64)
        self.radiance = np.asarray(radiance, dtype=np.float64).reshape(3, -1)
        self.two_sided = np.asarray(two_sided, dtype=bool)
        self.light_of = np.asarray(light_of, dtype=np.int64)
        self.area = mesh.area[self.triangles]
        self.emitter_of_triangle = np.full(mesh.triangle_count, -1, dtype=np.int32)
        self.emitter_of_triangle[self.triangles] = np.arange(self.triangles.size, dtype=np.int32)
        # Emitted power of each triangle: pi * area * mean RGB radiance per side.
        self.power = np.pi * self.area * self.radiance.mean(axis=0) * np.where(self.two_sided, 2.0, 1.0)
        if self.triangles.size == 0:
            self.pmf = np.zeros(0)
        elif selection == "power":
            self.pmf = self.power / self.power.sum()
        else:
            light_area = np.bincount(self.light_of, weights=self.area)
            light_count = np.count_nonzero(light_area)
            self.pmf = self.area / light_area[self.light_of] / light_count
        self.cdf = np.cumsum(self.pmf)
        if self.cdf.size:
            self.cdf /= self.cdf[-1]
        # pmf / area per emitter: the area density of a light sample on that triangle.
        self.pdf_area = np.divide(self.pmf, self.area, out=np.zeros_like(self.pmf), where=self.area > 0)
        self.table = np.take(mesh.table, self.triangles, axis=1)  # geometry rows of the emitting triangles

    @property
    def count(self) -> int:
        """Number of emitting triangles."""
        return int(self.triangles.size)

    def __repr__(self) -> str:
        return (f"AreaLights({self.count} triangles in {len(np.unique(self.light_of))} lights, "
                f"total power {self.power.sum():.6g} W, selection={self.selection!r})")

    def sample(self, receivers: np.ndarray, u: np.ndarray) -> LightSample:
        """Sample a point on the lights for each receiver point (3, N); u: (3, N) uniforms in [0, 1)."""
        emitter = np.minimum(np.searchsorted(self.cdf, u[0], side="right"), self.count - 1)
        b1, b2 = square_to_uniform_triangle(u[1:3])
        rows = np.take(self.table, emitter, axis=1)
        point = rows[0:3] + rows[3:6] * b1.astype(np.float32) + rows[6:9] * b2.astype(np.float32)
        normal = rows[9:12]
        wi = point - receivers
        dist2 = dot(wi, wi)
        distance = np.sqrt(dist2)
        wi /= distance
        cos_light = -dot(normal, wi)
        facing = self.two_sided.take(emitter) | (cos_light > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            pdf_sa = self.pdf_area.take(emitter) * dist2.astype(np.float64) / np.abs(cos_light).astype(np.float64)
        return LightSample(wi, distance, point, normal, np.take(self.radiance, emitter, axis=1), facing, pdf_sa,
                           cos_light)

    def pdf_sa(self, tri: np.ndarray, distance: np.ndarray, cos_light: np.ndarray) -> np.ndarray:
        """Solid-angle pdf with which :meth:`sample` would have produced a point on triangle ``tri``.

        ``distance`` from the receiver and ``cos_light`` at the light; triangles
        that do not emit have pdf 0.
        """
        emitter = self.emitter_of_triangle.take(tri)
        pdf_area = np.where(emitter >= 0, self.pdf_area.take(np.maximum(emitter, 0)), 0.0)
        d = distance.astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            return pdf_area * d * d / np.abs(cos_light).astype(np.float64)

    def emitted(self, tri: np.ndarray, cos_light: np.ndarray) -> np.ndarray:
        """Radiance (3, N) leaving triangles ``tri`` toward a viewer at dot(n, w_view) = ``cos_light``."""
        emitter = self.emitter_of_triangle.take(tri)
        e = np.maximum(emitter, 0)
        facing = (emitter >= 0) & (self.two_sided.take(e) | (cos_light > 0))
        return np.take(self.radiance, e, axis=1) * facing
