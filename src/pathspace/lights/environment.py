"""A constant environment: radiance L arriving from every direction at infinity.

Sampled uniformly over the sphere of directions (density 1 / (4 pi)).  Rays
that leave the scene see L.  Its power, for light selection, is that of the
radiance crossing the scene's bounding sphere: 4 pi^2 r^2 mean(L), as pbrt-v4.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Environment"]


@dataclass(frozen=True)
class Environment:
    """Constant environment light of RGB ``radiance``."""

    radiance: tuple[float, float, float]
    kind = "environment"

    def __post_init__(self) -> None:
        v = np.asarray(self.radiance, dtype=np.float64)
        if v.shape != (3,) or not np.all(np.isfinite(v)) or np.any(v < 0) or not np.any(v > 0):
            raise ValueError(f"radiance: expected 3 finite numbers >= 0, at least one > 0, got {self.radiance!r}")

    def power(self, scene_radius: float) -> float:
        return 4.0 * np.pi * np.pi * scene_radius ** 2 * float(np.mean(self.radiance))
