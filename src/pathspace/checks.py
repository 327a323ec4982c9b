"""Validation of model parameters given from Python: triples of numbers with ranges.

Errors read "name: expected ..., got ...", so that the scene loader can turn
them into messages naming the file and field.
"""
from __future__ import annotations

import numpy as np

__all__ = ["triple"]


def triple(value, name: str, *, low: float | None = None, high: float | None = None,
           some_positive: bool = False) -> np.ndarray:
    """``value`` as a float64 array of 3 finite numbers in [low, high] (and at least one > 0 if asked)."""
    v = np.asarray(value, dtype=np.float64)
    ok = v.shape == (3,) and bool(np.all(np.isfinite(v)))
    ok = ok and (low is None or bool(np.all(v >= low))) and (high is None or bool(np.all(v <= high)))
    ok = ok and (not some_positive or bool(np.any(v > 0)))
    if not ok:
        bounds = f" in [{low:g}, {high:g}]" if low is not None and high is not None else (
            f" >= {low:g}" if low is not None else "")
        extra = ", at least one > 0" if some_positive else ""
        raise ValueError(f"{name}: expected 3 finite numbers{bounds}{extra}, got {value!r}")
    return v
