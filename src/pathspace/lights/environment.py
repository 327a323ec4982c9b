"""A constant environment: radiance L arriving from every direction at infinity.

Sampled uniformly over the sphere of directions (density 1 / (4 pi)).  Rays
that leave the scene see L.  Its power, for light selection, is that of the
radiance crossing the scene's bounding sphere: 4 pi^2 r^2 mean(L), as pbrt-v4.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..spectra import Colour, check_emission, mean_rgb

__all__ = ["Environment"]


@dataclass(frozen=True)
class Environment:
    """Constant environment light of RGB ``radiance``."""

    radiance: Colour
    kind = "environment"

    def __post_init__(self) -> None:
        object.__setattr__(self, "radiance", check_emission(self.radiance, "radiance"))

    def power(self, scene_radius: float) -> float:
        return 4.0 * np.pi * np.pi * scene_radius ** 2 * mean_rgb(self.radiance)
