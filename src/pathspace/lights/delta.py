"""Lights with a delta distribution: point and spot lights (delta in position), directional lights
(delta in direction).  No ray can hit them, so only light sampling reaches them; they take no part
in MIS.  Their ``value`` at a receiver is the irradiance-like factor that multiplies f |cos| / pmf:

    point:        I / d^2
    spot:         I smoothstep(cos_total, cos_falloff_start, cos theta) / d^2   (pbrt-v4's falloff)
    directional:  E (irradiance on a surface facing the light)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..checks import triple
from ..spectra import Colour, check_emission, mean_rgb

__all__ = ["PointLight", "SpotLight", "DirectionalLight"]


@dataclass(frozen=True)
class PointLight:
    """Isotropic point light at ``position`` with RGB radiant intensity ``intensity`` (W/sr)."""

    position: tuple[float, float, float]
    intensity: Colour
    kind = "point"

    def __post_init__(self) -> None:
        triple(self.position, "position")
        object.__setattr__(self, "intensity", check_emission(self.intensity, "intensity"))

    @property
    def power(self) -> float:
        return 4.0 * np.pi * mean_rgb(self.intensity)

    def falloff(self, direction_from_light: np.ndarray) -> np.ndarray:
        return np.ones(direction_from_light.shape[1])


@dataclass(frozen=True)
class SpotLight:
    """Point light emitting toward ``look_at`` within ``cone_angle`` degrees of its axis.

    Full intensity within ``falloff_start`` degrees, smoothly falling to zero at
    ``cone_angle`` (pbrt-v4's smoothstep falloff).
    """

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    intensity: Colour
    cone_angle: float = 30.0
    falloff_start: float = 25.0
    kind = "spot"

    def __post_init__(self) -> None:
        p = triple(self.position, "position")
        if np.linalg.norm(triple(self.look_at, "look_at") - p) == 0:
            raise ValueError("look_at: must differ from position")
        object.__setattr__(self, "intensity", check_emission(self.intensity, "intensity"))
        if not (0 < self.cone_angle <= 90 and 0 <= self.falloff_start <= self.cone_angle):
            raise ValueError(f"cone_angle, falloff_start: expected 0 < falloff_start <= cone_angle <= 90 degrees, "
                             f"got {self.falloff_start}, {self.cone_angle}")

    @property
    def axis(self) -> np.ndarray:
        d = np.asarray(self.look_at, dtype=np.float64) - np.asarray(self.position, dtype=np.float64)
        return d / np.linalg.norm(d)

    @property
    def cos_cone(self) -> float:
        """Cosine of ``cone_angle``: directions beyond it get no light."""
        return float(np.cos(np.radians(self.cone_angle)))

    @property
    def cone_density(self) -> float:
        """Solid-angle density of directions uniform within the cone, 1 / (2 pi (1 - cos_cone))."""
        return 1.0 / (2 * np.pi * (1.0 - self.cos_cone))

    @property
    def power(self) -> float:
        cos_start, cos_end = np.cos(np.radians(self.falloff_start)), np.cos(np.radians(self.cone_angle))
        return mean_rgb(self.intensity) * 2.0 * np.pi * ((1.0 - cos_start) + (cos_start - cos_end) / 2.0)

    def falloff(self, direction_from_light: np.ndarray) -> np.ndarray:
        cos = self.axis @ direction_from_light
        cos_start, cos_end = np.cos(np.radians(self.falloff_start)), np.cos(np.radians(self.cone_angle))
        if cos_start <= cos_end:
            return (cos >= cos_end).astype(np.float64)
        x = np.clip((cos - cos_end) / (cos_start - cos_end), 0.0, 1.0)
        return x * x * (3.0 - 2.0 * x)


@dataclass(frozen=True)
class DirectionalLight:
    """Light arriving from infinitely far along ``direction`` (the way it travels) with irradiance ``irradiance``."""

    direction: tuple[float, float, float]
    irradiance: Colour
    kind = "directional"

    def __post_init__(self) -> None:
        if np.linalg.norm(triple(self.direction, "direction")) == 0:
            raise ValueError("direction: must not be the zero vector")
        object.__setattr__(self, "irradiance", check_emission(self.irradiance, "irradiance"))

    @property
    def unit_direction(self) -> np.ndarray:
        d = np.asarray(self.direction, dtype=np.float64)
        return d / np.linalg.norm(d)

    def power(self, scene_radius: float) -> float:
        return np.pi * scene_radius ** 2 * mean_rgb(self.irradiance)
