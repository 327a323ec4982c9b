"""The lights of a scene and next-event estimation's sampling of them.

A :class:`LightSet` holds the scene's area lights (emitting triangles),
point, spot and directional lights and an optional constant environment.
Sampling first picks an *entity* -- one emitting triangle, or one other
light -- from a discrete pmf, by power ("power": emitted power; triangles of
an area light in proportion to their power) or uniformly over lights
("uniform": every light equally likely, triangles of an area light by area),
then samples a point or direction on it.

Densities are in solid angle at the receiver and include the selection pmf;
for delta lights (point, spot, directional) the "pdf" is the pmf alone and
the sample is flagged ``delta``.
"""
from __future__ import annotations

from functools import cached_property

import numpy as np

from .. import warp
from ..spectra import ColourTable
from ..vecmath import dot, leave_distance, orthonormal_basis
from .area import MEASURES, AreaLights
from .delta import DirectionalLight, PointLight, SpotLight
from .environment import Environment

__all__ = ["AreaLights", "DirectionalLight", "EmissionSample", "Environment", "LightSample", "LightSet", "MEASURES",
           "PointLight", "SELECTIONS", "SpotLight"]

SELECTIONS = ("power", "uniform")
AREA, POINT, SPOT, DIRECTIONAL, ENVIRONMENT = range(5)


class EmissionSample:
    """A ray leaving a light (for light subpaths), one per lane.

    ``pdf_pos``: density of the origin including the selection pmf -- in area
    measure for area lights, 1 x pmf for point and spot lights (a delta),
    and for infinite lights the density on the disk the rays start from.
    ``pdf_dir``: solid-angle density of the direction (1 for a directional
    light's delta direction).  ``value``: radiance (area, environment),
    intensity (point, spot) or irradiance (directional) carried by the ray.
    The ray starts at ``point``, ``tmin`` along ``direction`` (see
    :func:`pathspace.vecmath.leave_distance`; ``epsilon``: the ray offset of
    an area light's surface, else 0); for infinite lights ``point`` lies on a
    disk outside the scene and ``normal`` is the direction; point and spot
    lights have a zero ``normal``.
    """

    __slots__ = ("point", "tmin", "epsilon", "normal", "direction", "value", "pdf_pos", "pdf_dir", "entity",
                 "infinite", "cos_light")

    def __init__(self, **fields):
        for name in self.__slots__:
            setattr(self, name, fields[name])


class LightSample:
    """One light sample per receiver (N lanes)."""

    __slots__ = ("wi", "distance", "point", "normal", "value", "facing", "pdf", "delta", "cos_light", "epsilon",
                 "entity")

    def __init__(self, wi, distance, point, normal, value, facing, pdf, delta, cos_light, epsilon, entity):
        self.wi = wi                # (3, N) float32 unit, receiver -> light
        self.distance = distance    # (N,) float32; inf for directional and environment samples
        self.point = point          # (3, N) float32 point on the light (finite lights)
        self.normal = normal        # (3, N) float32 light surface normal (area lights; else zero)
        self.value = value          # (C, N) float64: radiance, or I / d^2, or irradiance (see module doc)
        self.facing = facing        # (N,) bool: the light emits toward the receiver (one-sided area lights)
        self.pdf = pdf              # (N,) float64 solid-angle pdf times the selection pmf; pmf alone if delta
        self.delta = delta          # (N,) bool
        self.cos_light = cos_light  # (N,) float32 dot(normal, -wi) for area lights; 1 otherwise
        self.epsilon = epsilon      # (N,) float32 ray offset of the light's surface (area lights; else 0)
        self.entity = entity        # (N,) int64 the sampled entity (see LightSet)


class LightSet:
    """All lights of a scene; see the module docstring."""

    def __init__(self, area: AreaLights, others: list, scene_radius: float, disk_center, disk_radius: float) -> None:
        """``scene_radius``: of a sphere holding all geometry; the power of an infinite light (for light
        selection) is what crosses it.  ``disk_center``, ``disk_radius``: a sphere holding all geometry
        and the camera's lens (a thin lens can be hit); rays from infinite lights start on a disk just
        outside it (:meth:`sample_emission`)."""
        self.area = area
        self.points = [light for light in others if isinstance(light, PointLight)]
        self.spots = [light for light in others if isinstance(light, SpotLight)]
        self.directionals = [light for light in others if isinstance(light, DirectionalLight)]
        environments = [light for light in others if isinstance(light, Environment)]
        if len(environments) > 1:
            raise ValueError("at most one environment light is supported")
        self.environment = environments[0] if environments else None
        self.others = list(others)
        self.scene_radius = float(scene_radius)
        self.disk_center = np.asarray(disk_center, dtype=np.float64)
        self.disk_radius = float(disk_radius) * 1.01 + 1e-30
        kinds = [np.full(area.count, AREA)]
        index = [np.arange(area.count)]
        power = [area.power]
        for kind, group in ((POINT, self.points), (SPOT, self.spots), (DIRECTIONAL, self.directionals)):
            kinds.append(np.full(len(group), kind))
            index.append(np.arange(len(group)))
            power.append(np.array([l.power if kind != DIRECTIONAL else l.power(self.scene_radius) for l in group]))
        if self.environment is not None:
            kinds.append(np.array([ENVIRONMENT]))
            index.append(np.array([0]))
            power.append(np.array([self.environment.power(self.scene_radius)]))
        self.kind = np.concatenate(kinds).astype(np.int64)
        self.index = np.concatenate(index).astype(np.int64)
        self.power = np.concatenate(power).astype(np.float64)
        # Light id of every entity: area triangles share their shape's id.
        others_ids = area.light_count + np.arange(self.kind.size - area.count)
        _, area_ids = np.unique(area.light_of, return_inverse=True)
        self.light_id = np.concatenate([area_ids.ravel(), others_ids]).astype(np.int64)
        self.point_intensity = ColourTable([l.intensity for l in self.points], "illuminant")
        self.spot_intensity = ColourTable([l.intensity for l in self.spots], "illuminant")
        self.directional_irradiance = ColourTable([l.irradiance for l in self.directionals], "illuminant")
        self.environment_table = ColourTable([self.environment.radiance] if self.environment else [], "illuminant")

    @property
    def count(self) -> int:
        """Number of sampling entities (emitting triangles count one each)."""
        return int(self.kind.size)

    @property
    def has_delta(self) -> bool:
        """Whether some light cannot be hit by rays."""
        return bool(self.points or self.spots or self.directionals)

    def __repr__(self) -> str:
        parts = [f"{self.area.count} emitting triangles in {self.area.light_count} area lights"]
        for name, group in (("point", self.points), ("spot", self.spots), ("directional", self.directionals)):
            if group:
                parts.append(f"{len(group)} {name}")
        if self.environment is not None:
            parts.append("a constant environment")
        return f"LightSet({', '.join(parts)}; total power {self.power.sum():.6g} W)"

    @cached_property
    def _pmfs(self) -> dict[str, np.ndarray]:
        pmfs = {}
        if self.count == 0:
            return {s: np.zeros(0) for s in SELECTIONS}
        pmfs["power"] = self.power / self.power.sum()
        weight = np.ones(self.count)
        weight[: self.area.count] = self.area.area  # by area within a light
        per_light = np.bincount(self.light_id, weights=weight)
        pmfs["uniform"] = weight / per_light[self.light_id] / per_light.size
        return pmfs

    def pmf(self, selection: str) -> np.ndarray:
        """Selection probability of every entity."""
        if selection not in SELECTIONS:
            raise ValueError(f"light selection: expected one of {SELECTIONS}, got {selection!r}")
        return self._pmfs[selection]

    @cached_property
    def _cdfs(self) -> dict[str, np.ndarray]:
        cdfs = {}
        for selection in SELECTIONS:
            cdf = np.cumsum(self.pmf(selection))
            cdfs[selection] = cdf / cdf[-1] if cdf.size else cdf
        return cdfs

    def sample(self, receivers: np.ndarray, u: np.ndarray, colours, selection: str = "power",
               measure: str = "area") -> LightSample:
        """One light sample per receiver point (3, N) from uniforms u (3, N)."""
        count = receivers.shape[1]
        entity = np.minimum(np.searchsorted(self._cdfs[selection], u[0], side="right"), self.count - 1)
        pmf = self.pmf(selection).take(entity)
        kind = self.kind.take(entity)
        if self.count == self.area.count:  # only area lights: no dispatch
            return self._sample_area(self.index.take(entity), receivers, u[1:3], pmf, colours, measure, entity)
        wi = np.zeros((3, count), dtype=np.float32)
        distance = np.full(count, np.inf, dtype=np.float32)
        point = np.zeros((3, count), dtype=np.float32)
        normal = np.zeros((3, count), dtype=np.float32)
        value = np.zeros((colours.channels, count))
        facing = np.ones(count, dtype=bool)
        pdf = np.zeros(count)
        delta = np.zeros(count, dtype=bool)
        cos_light = np.ones(count, dtype=np.float32)
        epsilon = np.zeros(count, dtype=np.float32)
        for k in np.unique(kind):
            lanes = np.flatnonzero(kind == k)
            idx, ref, uu = self.index.take(entity.take(lanes)), np.take(receivers, lanes, axis=1), u[1:3, lanes]
            mine = colours.take(lanes)
            if k == AREA:
                s = self._sample_area(idx, ref, uu, pmf.take(lanes), mine, measure, entity.take(lanes))
                wi[:, lanes], distance[lanes], point[:, lanes], normal[:, lanes] = s.wi, s.distance, s.point, s.normal
                value[:, lanes], facing[lanes], pdf[lanes], cos_light[lanes] = s.value, s.facing, s.pdf, s.cos_light
                epsilon[lanes] = s.epsilon
                continue
            if k == ENVIRONMENT:
                d = warp.square_to_uniform_sphere(uu)
                wi[:, lanes] = d
                value[:, lanes] = mine.lookup(self.environment_table, np.zeros(lanes.size, dtype=np.int64))
                pdf[lanes] = pmf.take(lanes) * warp.INV_FOUR_PI
                continue
            delta[lanes] = True
            pdf[lanes] = pmf.take(lanes)
            if k == DIRECTIONAL:
                travel = np.array([l.unit_direction for l in self.directionals]).T.take(idx, axis=1)
                wi[:, lanes] = -travel
                value[:, lanes] = mine.lookup(self.directional_irradiance, idx)
                continue
            lights = self.points if k == POINT else self.spots
            position = np.array([l.position for l in lights], dtype=np.float64).T.take(idx, axis=1)
            to_light = position - ref
            dist2 = dot(to_light, to_light)
            dist = np.sqrt(dist2)
            direction = to_light / dist
            intensity = (self.point_intensity if k == POINT else self.spot_intensity)
            falloff = np.ones(lanes.size)
            if k == SPOT:
                for j in np.unique(idx):
                    this_spot = idx == j
                    falloff[this_spot] = self.spots[j].falloff(-direction[:, this_spot])
            wi[:, lanes] = direction
            distance[lanes] = dist
            point[:, lanes] = position
            value[:, lanes] = mine.lookup(intensity, idx) * (falloff / dist2)
        return LightSample(wi, distance, point, normal, value, facing, pdf, delta, cos_light, epsilon, entity)

    def _sample_area(self, emitter, receivers, u, pmf, colours, measure, entity) -> LightSample:
        point, normal, wi, distance, cos_light, pdf = self.area.sample(emitter, receivers, u, measure)
        facing = self.area.two_sided.take(emitter) | (cos_light > 0)
        return LightSample(wi, distance, point, normal, self.area.radiance_of(emitter, colours), facing,
                           pdf * pmf, np.zeros(pmf.shape, dtype=bool), cos_light, self.area.table[12].take(emitter),
                           entity)

    def pdf_hit(self, triangles: np.ndarray, receivers: np.ndarray, points: np.ndarray, selection: str = "power",
                measure: str = "area") -> np.ndarray:
        """Density (solid angle, with the pmf) with which :meth:`sample` produces ``points`` on ``triangles``.

        ``receivers`` are the points the samples would be taken from.
        Triangles that do not emit get density 0.
        """
        emitter = self.area.emitter_of_triangle.take(triangles)
        emits = emitter >= 0
        safe = np.where(emits, emitter, 0)
        pmf = self.pmf(selection)[: self.area.count].take(safe)
        return np.where(emits, pmf * self.area.pdf_sa(safe, receivers, points, measure), 0.0)

    def pdf_environment(self, selection: str = "power") -> float:
        """Density (solid angle, with the pmf) of sampling any given direction of the environment."""
        if self.environment is None:
            return 0.0
        return float(self.pmf(selection)[-1]) * warp.INV_FOUR_PI

    def environment_radiance(self, count: int, colours) -> np.ndarray:
        """Radiance (C, count) of the environment (zero if there is none)."""
        if self.environment is None:
            return np.zeros((colours.channels, count))
        return colours.lookup(self.environment_table, np.zeros(count, dtype=np.int64))

    def sample_emission(self, u: np.ndarray, colours, selection: str) -> EmissionSample:
        """Sample rays leaving the lights: an entity by ``selection``, a point, a direction (u: (5, N))."""
        count = u.shape[1]
        entity = np.minimum(np.searchsorted(self._cdfs[selection], u[0], side="right"), self.count - 1)
        pmf = self.pmf(selection).take(entity)
        kind, index = self.kind.take(entity), self.index.take(entity)
        point = np.zeros((3, count), dtype=np.float32)
        tmin = np.zeros(count, dtype=np.float32)
        epsilon = np.zeros(count, dtype=np.float32)
        normal = np.zeros((3, count), dtype=np.float32)
        direction = np.zeros((3, count), dtype=np.float32)
        value = np.zeros((colours.channels, count))
        pdf_pos = np.zeros(count)
        pdf_dir = np.ones(count)
        cos_light = np.ones(count)
        radius = self.disk_radius
        for k in np.unique(kind):
            lanes = np.flatnonzero(kind == k)
            idx, mine = index.take(lanes), colours.take(lanes)
            if k == AREA:
                rows, p = self.area.uniform_points(idx, u[1:3, lanes])
                n = rows[9:12]
                two = self.area.two_sided.take(idx)
                side = np.where(two & (u[3, lanes] < 0.5), np.float32(-1), np.float32(1))
                u_side = np.where(two, (u[3, lanes] * 2) % 1.0, u[3, lanes])  # reused after choosing a side
                d = warp.square_to_cosine_about(n * side, np.stack((u_side, u[4, lanes])))
                cos = np.abs(dot(n, d)).astype(np.float64)
                point[:, lanes], normal[:, lanes], direction[:, lanes] = p, n, d
                tmin[lanes] = leave_distance(rows[12], dot(n, d))
                epsilon[lanes] = rows[12]
                value[:, lanes] = self.area.radiance_of(idx, mine)
                pdf_pos[lanes] = pmf.take(lanes) / self.area.area.take(idx)
                pdf_dir[lanes] = cos * warp.INV_PI * np.where(two, 0.5, 1.0)
                cos_light[lanes] = cos
            elif k in (POINT, SPOT):
                lights = self.points if k == POINT else self.spots
                position = np.array([l.position for l in lights], dtype=np.float64).T.take(idx, axis=1)
                if k == POINT:
                    d = warp.square_to_uniform_sphere(u[1:3, lanes])
                    density = np.full(lanes.size, warp.INV_FOUR_PI)
                    falloff = np.ones(lanes.size)
                else:
                    d, density, falloff = self._sample_spot(idx, u[1:3, lanes])
                point[:, lanes] = position
                direction[:, lanes] = d
                value[:, lanes] = mine.lookup(self.point_intensity if k == POINT else self.spot_intensity, idx) * falloff
                pdf_pos[lanes] = pmf.take(lanes)
                pdf_dir[lanes] = density
            else:  # directional or environment: rays from a disk facing the scene, outside it
                if k == DIRECTIONAL:
                    d = np.array([l.unit_direction for l in self.directionals]).T.take(idx, axis=1).astype(np.float32)
                    value[:, lanes] = mine.lookup(self.directional_irradiance, idx)
                else:
                    d = warp.square_to_uniform_sphere(u[1:3, lanes])
                    value[:, lanes] = mine.lookup(self.environment_table, np.zeros(lanes.size, dtype=np.int64))
                    pdf_dir[lanes] = warp.INV_FOUR_PI
                s, t = orthonormal_basis(d.astype(np.float64))
                r = radius * np.sqrt(u[3, lanes])
                phi = 2 * np.pi * u[4, lanes]
                start = self.disk_center[:, None] - d * radius + s * (r * np.cos(phi)) + t * (r * np.sin(phi))
                point[:, lanes] = start
                direction[:, lanes] = d
                normal[:, lanes] = d
                pdf_pos[lanes] = pmf.take(lanes) / (np.pi * radius * radius)
        infinite = (kind == DIRECTIONAL) | (kind == ENVIRONMENT)
        return EmissionSample(point=point, tmin=tmin, epsilon=epsilon, normal=normal, direction=direction, value=value,
                              pdf_pos=pdf_pos, pdf_dir=pdf_dir, entity=entity, infinite=infinite, cos_light=cos_light)

    def _sample_spot(self, idx: np.ndarray, u: np.ndarray):
        """Directions uniform within each spot light's cone, their solid-angle density and the falloff."""
        d = np.zeros((3, idx.size), dtype=np.float32)
        density = np.zeros(idx.size)
        falloff = np.zeros(idx.size)
        for j in np.unique(idx):
            lanes = np.flatnonzero(idx == j)
            spot = self.spots[j]
            cos_theta = 1.0 - u[0, lanes] * (1.0 - spot.cos_cone)
            sin_theta = np.sqrt(np.maximum(0.0, 1.0 - cos_theta * cos_theta))
            phi = 2 * np.pi * u[1, lanes]
            axis = np.repeat(spot.axis[:, None], lanes.size, axis=1)
            s, t = orthonormal_basis(axis)
            d[:, lanes] = s * (sin_theta * np.cos(phi)) + t * (sin_theta * np.sin(phi)) + axis * cos_theta
            density[lanes] = spot.cone_density
            falloff[lanes] = spot.falloff(d[:, lanes].astype(np.float64))
        return d, density, falloff

    def origin_pdf(self, entity: np.ndarray, selection: str = "power") -> np.ndarray:
        """Density, with the selection pmf, of the point :meth:`sample_emission` starts from on ``entity``
        (pbrt's PdfLightOrigin): per area for area lights; the pmf alone for point, spot and directional
        lights (a delta); per solid angle of the direction for the environment."""
        kind = self.kind.take(entity)
        per = np.ones(entity.size)
        on_area = np.flatnonzero(kind == AREA)
        per[on_area] = 1.0 / self.area.area.take(self.index.take(entity.take(on_area)))
        per[kind == ENVIRONMENT] = warp.INV_FOUR_PI
        return self.pmf(selection).take(entity) * per

    def emitted_toward(self, entity: np.ndarray, normal: np.ndarray, direction: np.ndarray, colours) -> np.ndarray:
        """What finite lights ``entity`` send along unit ``direction`` (3, N), (C, N): radiance times |cos|
        at a point with geometric normal ``normal`` (area lights; 0 behind one-sided ones), intensity
        (point lights), intensity times falloff (spot lights).  Infinite lights: 0."""
        kind, index = self.kind.take(entity), self.index.take(entity)
        out = np.zeros((colours.channels, entity.size))
        for k in np.unique(kind):
            lanes = np.flatnonzero(kind == k)
            idx, mine = index.take(lanes), colours.take(lanes)
            d = np.take(direction, lanes, axis=1)
            if k == AREA:
                cos = dot(np.take(normal, lanes, axis=1), d).astype(np.float64)
                out[:, lanes] = self.area.emitted(idx, cos, mine) * np.abs(cos)
            elif k == POINT:
                out[:, lanes] = mine.lookup(self.point_intensity, idx)
            elif k == SPOT:
                falloff = np.zeros(lanes.size)
                for j in np.unique(idx):
                    this_spot = idx == j
                    falloff[this_spot] = self.spots[j].falloff(d[:, this_spot].astype(np.float64))
                out[:, lanes] = mine.lookup(self.spot_intensity, idx) * falloff
        return out

    def emission_pdf_dir(self, entity: np.ndarray, normal: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """Solid-angle density with which :meth:`sample_emission` emits ``direction`` from finite lights ``entity``
        (area: from a point with geometric normal ``normal``).  Infinite lights: the disk density instead (which
        multiplies |cos| at the receiver rather than converting by distance)."""
        kind, index = self.kind.take(entity), self.index.take(entity)
        out = np.zeros(entity.size)
        for k in np.unique(kind):
            lanes = np.flatnonzero(kind == k)
            idx = index.take(lanes)
            if k == AREA:
                cos = dot(np.take(normal, lanes, axis=1), np.take(direction, lanes, axis=1)).astype(np.float64)
                two = self.area.two_sided.take(idx)
                out[lanes] = np.where(two, np.abs(cos) * 0.5, np.maximum(cos, 0.0)) * warp.INV_PI
            elif k == POINT:
                out[lanes] = warp.INV_FOUR_PI
            elif k == SPOT:
                for j in np.unique(idx):
                    mine = lanes[idx == j]
                    spot = self.spots[j]
                    inside = spot.axis @ np.take(direction, mine, axis=1).astype(np.float64) >= spot.cos_cone
                    out[mine] = np.where(inside, spot.cone_density, 0.0)
            else:
                radius = self.disk_radius
                out[lanes] = 1.0 / (np.pi * radius * radius)
        return out
