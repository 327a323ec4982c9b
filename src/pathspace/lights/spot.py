"""Spot lights: a point light emitting into a cone, with pbrt-v4's smooth falloff.

Radiant intensity I within ``falloff_start`` degrees of the axis, falling
smoothly (smoothstep in cos theta) to zero at ``cone_angle``.  A delta in
position like a point light: value I falloff / d^2 at a receiver; emitted
rays are uniform within the cone.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from ..checks import triple
from ..spectra import Colour, ColourTable, check_emission
from ..vecmath import dot, orthonormal_basis
from .base import EmissionSample, Light, LightContext, LightSample
from .point import PointTables, delta_light_sample

if TYPE_CHECKING:
    from ..fields import Fields

__all__ = ["SpotLight", "SpotTables"]


@dataclass(frozen=True)
class SpotLight(Light):
    """Point light at ``position`` emitting toward ``look_at`` within ``cone_angle`` degrees of its axis,
    at full intensity within ``falloff_start`` degrees."""

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    intensity: Colour
    cone_angle: float = 30.0
    falloff_start: float = 25.0
    kind = "spot"
    delta = True

    def __post_init__(self) -> None:
        p = triple(self.position, "position")
        if np.linalg.norm(triple(self.look_at, "look_at") - p) == 0:
            raise ValueError("look_at: must differ from position")
        object.__setattr__(self, "intensity", check_emission(self.intensity, "intensity"))
        if not (0 < self.cone_angle <= 90 and 0 <= self.falloff_start <= self.cone_angle):
            raise ValueError(f"cone_angle, falloff_start: expected 0 < falloff_start <= cone_angle <= 90 degrees, "
                             f"got {self.falloff_start}, {self.cone_angle}")

    def translated(self, offset: np.ndarray) -> "SpotLight":
        """The light moved by ``offset`` (3,) (into the scene's render space)."""
        return replace(self, position=tuple(np.add(self.position, offset).tolist()),
                       look_at=tuple(np.add(self.look_at, offset).tolist()))

    @classmethod
    def from_fields(cls, fields: "Fields") -> "SpotLight":
        """A ``[[lights]]`` table of type "spot": ``position``, ``look_at``, ``intensity``, ``cone_angle``
        (default 30), ``falloff_start`` (default 25, at most the cone angle)."""
        position, look_at = tuple(fields.point("position")), tuple(fields.point("look_at"))
        intensity = fields.colour("intensity")
        cone = fields.number("cone_angle", 30.0, low=0.0, high=90.0, low_open=True)
        start = fields.number("falloff_start", min(25.0, cone), low=0.0, high=cone)
        fields.finish()
        return fields.build(lambda: cls(position, look_at, intensity, cone, start))

    @property
    def axis(self) -> np.ndarray:
        """Unit direction from the position toward ``look_at``."""
        d = np.asarray(self.look_at, dtype=np.float64) - np.asarray(self.position, dtype=np.float64)
        return d / np.linalg.norm(d)

    @property
    def cos_cone(self) -> float:
        """Cosine of ``cone_angle``: directions beyond it get no light."""
        return float(np.cos(np.radians(self.cone_angle)))

    @property
    def cos_falloff_start(self) -> float:
        """Cosine of ``falloff_start``."""
        return float(np.cos(np.radians(self.falloff_start)))

    @staticmethod
    def tables(lights: list["SpotLight"], context: LightContext) -> "SpotTables":
        """Positions, intensities, axes and cone cosines."""
        return SpotTables(np.array([light.position for light in lights], dtype=np.float64).reshape(-1, 3).T,
                          ColourTable([light.intensity for light in lights], "illuminant"),
                          np.array([light.axis for light in lights]).reshape(-1, 3).T,
                          np.array([light.cos_cone for light in lights]),
                          np.array([light.cos_falloff_start for light in lights]))

    @staticmethod
    def power(tables: "SpotTables", context: LightContext) -> np.ndarray:
        """Intensity integrated over the cone with its falloff (pbrt-v4's Phi)."""
        cos_start, cos_end = tables.cos_start, tables.cos_cone
        return tables.intensity.mean() * 2.0 * np.pi * ((1.0 - cos_start) + (cos_start - cos_end) / 2.0)

    @staticmethod
    def sample_li(tables: "SpotTables", idx, receivers, u, colours, measure: str) -> LightSample:
        """The light's position, with value I falloff / d^2."""
        return delta_light_sample(tables, idx, receivers, colours, tables.falloff)

    @staticmethod
    def sample_le(tables: "SpotTables", idx, u, colours, context: LightContext) -> EmissionSample:
        """Directions uniform within the cone."""
        cos_cone = tables.cos_cone.take(idx)
        cos_theta = 1.0 - u[0] * (1.0 - cos_cone)
        sin_theta = np.sqrt(np.maximum(0.0, 1.0 - cos_theta * cos_theta))
        phi = 2 * np.pi * u[1]
        axis = tables.axis.take(idx, axis=1)
        s, t = orthonormal_basis(axis)
        d = (s * (sin_theta * np.cos(phi)) + t * (sin_theta * np.sin(phi)) + axis * cos_theta).astype(np.float32)
        count = idx.size
        return EmissionSample(point=tables.position.take(idx, axis=1).astype(np.float32),
                              epsilon=np.zeros(count, np.float32), normal=np.zeros((3, count), np.float32), direction=d,
                              value=colours.lookup(tables.intensity, idx) * tables.falloff(idx, d.astype(np.float64)),
                              pdf_pos=np.ones(count), pdf_dir=tables.cone_density(idx), cos_light=np.ones(count))

    @staticmethod
    def pdf_le(tables: "SpotTables", idx, normal, direction, context: LightContext):
        """(1 for the delta position, uniform density within the cone)."""
        inside = dot(tables.axis.take(idx, axis=1), direction.astype(np.float64)) >= tables.cos_cone.take(idx)
        return np.ones(idx.size), np.where(inside, tables.cone_density(idx), 0.0)

    @staticmethod
    def le(tables: "SpotTables", idx, normal, direction, colours) -> np.ndarray:
        """The intensity times the falloff along ``direction``."""
        return colours.lookup(tables.intensity, idx) * tables.falloff(idx, direction.astype(np.float64))


@dataclass
class SpotTables(PointTables):
    """Point tables plus ``axis`` (3, K), ``cos_cone`` and ``cos_start`` (K,) of each spot light."""

    axis: np.ndarray
    cos_cone: np.ndarray
    cos_start: np.ndarray

    def cone_density(self, idx: np.ndarray) -> np.ndarray:
        """Solid-angle density of directions uniform within each cone, 1 / (2 pi (1 - cos_cone))."""
        return 1.0 / (2 * np.pi * (1.0 - self.cos_cone.take(idx)))

    def falloff(self, idx: np.ndarray, direction_from_light: np.ndarray) -> np.ndarray:
        """Smoothstep from the cone's edge to ``falloff_start`` (a hard edge if they coincide)."""
        cos = dot(self.axis.take(idx, axis=1), direction_from_light)
        cos_start, cos_end = self.cos_start.take(idx), self.cos_cone.take(idx)
        hard = cos_start <= cos_end
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.clip((cos - cos_end) / (cos_start - cos_end), 0.0, 1.0)
        return np.where(hard, (cos >= cos_end).astype(np.float64), x * x * (3.0 - 2.0 * x))
