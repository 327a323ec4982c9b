"""Point lights: isotropic radiant intensity I (W/sr) from one point, a delta in position.

No ray can hit a point light, so only light sampling reaches it; it takes
no part in MIS.  Seen from a receiver at distance d its value is I / d^2
(what multiplies f |cos| / pmf).  Emitted rays leave uniformly over the
sphere of directions.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from .. import warp
from ..checks import triple
from ..spectra import Colour, ColourTable, check_emission
from ..vecmath import dot
from .base import EmissionSample, Light, LightContext, LightSample

if TYPE_CHECKING:
    from ..fields import Fields

__all__ = ["PointLight", "PointTables", "delta_light_sample"]


@dataclass(frozen=True)
class PointLight(Light):
    """Isotropic point light at ``position`` with radiant intensity ``intensity`` (W/sr, RGB or a spectrum)."""

    position: tuple[float, float, float]
    intensity: Colour
    kind = "point"
    delta = True

    def __post_init__(self) -> None:
        triple(self.position, "position")
        object.__setattr__(self, "intensity", check_emission(self.intensity, "intensity"))

    def translated(self, offset: np.ndarray) -> "PointLight":
        """The light moved by ``offset`` (3,) (into the scene's render space)."""
        return replace(self, position=tuple(np.add(self.position, offset).tolist()))

    @classmethod
    def from_fields(cls, fields: "Fields") -> "PointLight":
        """A ``[[lights]]`` table of type "point": ``position``, ``intensity``."""
        position, intensity = tuple(fields.point("position")), fields.colour("intensity")
        fields.finish()
        return fields.build(lambda: cls(position, intensity))

    @staticmethod
    def tables(lights: list["PointLight"], context: LightContext) -> "PointTables":
        """Positions and intensities."""
        return PointTables(np.array([light.position for light in lights], dtype=np.float64).reshape(-1, 3).T,
                           ColourTable([light.intensity for light in lights], "illuminant"))

    @staticmethod
    def power(tables: "PointTables", context: LightContext) -> np.ndarray:
        """4 pi mean(I) per light."""
        return 4.0 * np.pi * tables.intensity.mean()

    @staticmethod
    def sample_li(tables: "PointTables", idx, receivers, u, colours, measure: str) -> LightSample:
        """The light's position, with value I / d^2."""
        return delta_light_sample(tables, idx, receivers, colours)

    @staticmethod
    def sample_le(tables: "PointTables", idx, u, colours, context: LightContext) -> EmissionSample:
        """Uniform directions from the light's position."""
        d = warp.square_to_uniform_sphere(u[0:2])
        return EmissionSample(point=tables.position.take(idx, axis=1).astype(np.float32),
                              epsilon=np.zeros(idx.size, np.float32), normal=np.zeros((3, idx.size), np.float32),
                              direction=d, value=colours.lookup(tables.intensity, idx),
                              pdf_pos=np.ones(idx.size), pdf_dir=np.full(idx.size, warp.INV_FOUR_PI),
                              cos_light=np.ones(idx.size))

    @staticmethod
    def pdf_le(tables: "PointTables", idx, normal, direction, context: LightContext):
        """(1 for the delta position, 1 / (4 pi))."""
        return np.ones(idx.size), np.full(idx.size, warp.INV_FOUR_PI)

    @staticmethod
    def le(tables: "PointTables", idx, normal, direction, colours) -> np.ndarray:
        """The intensity."""
        return colours.lookup(tables.intensity, idx)


@dataclass
class PointTables:
    """``position`` (3, K) float64 and ``intensity`` (a ColourTable) of the point (or spot) lights of a scene."""

    position: np.ndarray
    intensity: ColourTable


def delta_light_sample(tables: PointTables, idx, receivers, colours, falloff=None) -> LightSample:
    """A light sample of point-like lights at ``tables.position``: value I f / d^2, density 1 (a delta: the
    LightSet's selection pmf alone remains); f = ``falloff(idx, directions from the light)``, or 1."""
    position = tables.position.take(idx, axis=1)
    to_light = position - receivers
    dist2 = dot(to_light, to_light)
    dist = np.sqrt(dist2)
    direction = to_light / dist
    count = idx.size
    falloff = np.ones(count) if falloff is None else falloff(idx, -direction)
    return LightSample(wi=direction.astype(np.float32), distance=dist.astype(np.float32),
                       point=position.astype(np.float32), normal=np.zeros((3, count), np.float32),
                       value=colours.lookup(tables.intensity, idx) * (falloff / dist2), facing=np.ones(count, bool),
                       pdf=np.ones(count), delta=np.ones(count, bool),
                       epsilon=np.zeros(count, np.float32))
