"""Directional lights: irradiance E arriving from infinitely far along one direction (a delta in direction).

No ray can hit it; its value at a receiver is E, the irradiance on a
surface facing the light.  Emitted rays start on a disk outside the scene
(see :func:`pathspace.lights.base.disk_origins`).  Its power, for light
selection, is what crosses the scene's bounding sphere: pi r^2 mean(E).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..checks import triple
from ..spectra import Colour, ColourTable, check_emission
from .base import EmissionSample, Light, LightContext, LightSample, disk_origins

if TYPE_CHECKING:
    from ..fields import Fields

__all__ = ["DirectionalLight", "DirectionalTables"]


@dataclass(frozen=True)
class DirectionalLight(Light):
    """Light arriving from infinitely far along ``direction`` (the way it travels) with ``irradiance``."""

    direction: tuple[float, float, float]
    irradiance: Colour
    kind = "directional"
    delta = True
    infinite = True

    def __post_init__(self) -> None:
        if np.linalg.norm(triple(self.direction, "direction")) == 0:
            raise ValueError("direction: must not be the zero vector")
        object.__setattr__(self, "irradiance", check_emission(self.irradiance, "irradiance"))

    @classmethod
    def from_fields(cls, fields: "Fields") -> "DirectionalLight":
        """A ``[[lights]]`` table of type "directional": ``direction``, ``irradiance``."""
        direction, irradiance = tuple(fields.direction("direction")), fields.colour("irradiance")
        fields.finish()
        return fields.build(lambda: cls(direction, irradiance))

    @property
    def unit_direction(self) -> np.ndarray:
        """The direction of travel, normalised."""
        d = np.asarray(self.direction, dtype=np.float64)
        return d / np.linalg.norm(d)

    @staticmethod
    def tables(lights: list["DirectionalLight"], context: LightContext) -> "DirectionalTables":
        """Directions of travel and irradiances."""
        return DirectionalTables(np.array([light.unit_direction for light in lights]).reshape(-1, 3).T,
                                 ColourTable([light.irradiance for light in lights], "illuminant"))

    @staticmethod
    def power(tables: "DirectionalTables", context: LightContext) -> np.ndarray:
        """pi r^2 mean(E): what crosses the scene's bounding sphere."""
        return np.pi * context.scene_radius ** 2 * tables.irradiance.mean()

    @staticmethod
    def sample_li(tables: "DirectionalTables", idx, receivers, u, colours, measure: str) -> LightSample:
        """The direction toward the light, value E."""
        count = idx.size
        return LightSample(wi=(-tables.travel.take(idx, axis=1)).astype(np.float32),
                           distance=np.full(count, np.inf, np.float32), point=np.zeros((3, count), np.float32),
                           normal=np.zeros((3, count), np.float32), value=colours.lookup(tables.irradiance, idx),
                           facing=np.ones(count, bool), pdf=np.ones(count), delta=np.ones(count, bool),
                           epsilon=np.zeros(count, np.float32))

    @staticmethod
    def sample_le(tables: "DirectionalTables", idx, u, colours, context: LightContext) -> EmissionSample:
        """Parallel rays from a disk facing the scene."""
        count = idx.size
        d = tables.travel.take(idx, axis=1).astype(np.float32)
        return EmissionSample(point=disk_origins(context, d, u[2:4]).astype(np.float32),
                              epsilon=np.zeros(count, np.float32), normal=d,
                              direction=d, value=colours.lookup(tables.irradiance, idx),
                              pdf_pos=np.full(count, 1.0 / (np.pi * context.disk_radius ** 2)), pdf_dir=np.ones(count),
                              cos_light=np.ones(count))

    @staticmethod
    def pdf_le(tables: "DirectionalTables", idx, normal, direction, context: LightContext):
        """(1 for the delta direction, the disk density)."""
        return np.ones(idx.size), np.full(idx.size, 1.0 / (np.pi * context.disk_radius * context.disk_radius))

    @staticmethod
    def le(tables: "DirectionalTables", idx, normal, direction, colours) -> np.ndarray:
        """Nothing: no point of the scene emits it."""
        return np.zeros((colours.channels, idx.size))


@dataclass
class DirectionalTables:
    """``travel`` (3, K) unit directions of travel and ``irradiance`` (a ColourTable)."""

    travel: np.ndarray
    irradiance: ColourTable
