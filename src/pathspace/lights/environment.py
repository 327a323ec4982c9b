"""A constant environment: radiance L arriving from every direction at infinity.

Sampled uniformly over the sphere of directions (density 1 / (4 pi)).  Rays
that leave the scene see L.  Emitted rays start on a disk outside the scene
(see :func:`pathspace.lights.base.disk_origins`).  Its power, for light
selection, is that of the radiance crossing the scene's bounding sphere:
4 pi^2 r^2 mean(L), as pbrt-v4.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .. import warp
from ..spectra import Colour, ColourTable, check_emission
from .base import EmissionSample, Light, LightContext, LightSample, disk_origins

if TYPE_CHECKING:
    from ..fields import Fields

__all__ = ["Environment"]


@dataclass(frozen=True)
class Environment(Light):
    """Constant environment light of ``radiance`` (RGB or a spectrum); at most one per scene."""

    radiance: Colour
    kind = "environment"
    infinite = True
    hit_by_escaping_rays = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "radiance", check_emission(self.radiance, "radiance"))

    @classmethod
    def from_fields(cls, fields: "Fields") -> "Environment":
        """A ``[[lights]]`` table of type "environment": ``radiance``."""
        radiance = fields.colour("radiance")
        fields.finish()
        return fields.build(lambda: cls(radiance))

    @staticmethod
    def tables(lights: list["Environment"], context: LightContext) -> ColourTable:
        """The radiance."""
        if len(lights) > 1:
            raise ValueError("at most one environment light is supported")
        return ColourTable([light.radiance for light in lights], "illuminant")

    @staticmethod
    def power(tables: ColourTable, context: LightContext) -> np.ndarray:
        """4 pi^2 r^2 mean(L)."""
        return 4.0 * np.pi * np.pi * context.scene_radius ** 2 * tables.mean()

    @staticmethod
    def sample_li(tables: ColourTable, idx, receivers, u, colours, measure: str) -> LightSample:
        """A uniform direction."""
        count = idx.size
        return LightSample(wi=warp.square_to_uniform_sphere(u), distance=np.full(count, np.inf, np.float32),
                           point=np.zeros((3, count), np.float32), normal=np.zeros((3, count), np.float32),
                           value=colours.lookup(tables, idx), facing=np.ones(count, bool),
                           pdf=np.full(count, warp.INV_FOUR_PI), delta=np.zeros(count, bool),
                           epsilon=np.zeros(count, np.float32))

    @staticmethod
    def pdf_li(tables: ColourTable, idx, receivers, points, measure: str) -> np.ndarray:
        """1 / (4 pi) for every direction."""
        return np.full(idx.size, warp.INV_FOUR_PI)

    @staticmethod
    def sample_le(tables: ColourTable, idx, u, colours, context: LightContext) -> EmissionSample:
        """Uniform directions, from a disk facing the scene."""
        count = idx.size
        d = warp.square_to_uniform_sphere(u[0:2])
        return EmissionSample(point=disk_origins(context, d, u[2:4]).astype(np.float32),
                              epsilon=np.zeros(count, np.float32), normal=d,
                              direction=d, value=colours.lookup(tables, idx),
                              pdf_pos=np.full(count, 1.0 / (np.pi * context.disk_radius ** 2)),
                              pdf_dir=np.full(count, warp.INV_FOUR_PI), cos_light=np.ones(count))

    @staticmethod
    def pdf_le(tables: ColourTable, idx, normal, direction, context: LightContext):
        """(1 / (4 pi), the disk density): for lights at infinity the origin density is the direction's."""
        return (np.full(idx.size, warp.INV_FOUR_PI),
                np.full(idx.size, 1.0 / (np.pi * context.disk_radius * context.disk_radius)))

    @staticmethod
    def le(tables: ColourTable, idx, normal, direction, colours) -> np.ndarray:
        """The radiance."""
        return colours.lookup(tables, idx)
