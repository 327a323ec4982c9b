"""How colour parameters become per-lane values: the RGB colour model.

Scene colours are stored as (3, M) linear sRGB tables.  Estimators turn them
into per-lane (C, N) values through a colour model; in RGB rendering that
is a gather (C = 3).  Spectral rendering substitutes a model that evaluates
spectra at each lane's wavelengths, with the same interface.
"""
from __future__ import annotations

import numpy as np

__all__ = ["RGBColours"]


class RGBColours:
    """Per-lane RGB values: ``lookup`` for reflectances, ``lookup_unbounded`` for other colour quantities."""

    channels = 3

    @staticmethod
    def lookup(table: np.ndarray, ids: np.ndarray) -> np.ndarray:
        """Values of reflectance-like colours (in [0, 1]) ``table[:, ids]`` as (3, N) float64."""
        return np.take(table, ids, axis=1)

    # Unbounded colour quantities (radiance, indices of refraction) need a different spectral
    # representation; in RGB they are looked up the same way.
    lookup_unbounded = lookup
