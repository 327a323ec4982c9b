"""Validation of parameters given from Python: one wording for every error.

Every check returns the (normalised) value or raises ValueError reading
"name: expected ..., got ...", so that estimators, models and the scene
loader (which turns them into messages naming the file and field) all speak
the same way.
"""
from __future__ import annotations

import math
from typing import Any, Iterable

import numpy as np

__all__ = ["triple", "choice", "integer", "number", "expected"]


def expected(name: str, what: str, value: Any) -> ValueError:
    """The error "name: expected what, got value"."""
    return ValueError(f"{name}: expected {what}, got {value!r}")


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


def choice(value: Any, name: str, options: Iterable[str]) -> str:
    """``value`` if it is one of ``options``."""
    options = tuple(options)
    if not isinstance(value, str) or value not in options:
        raise expected(name, f"one of {options}", value)
    return value


def integer(value: Any, name: str, *, low: int | None = None, unbounded: int | None = None) -> int:
    """``value`` as an int >= ``low``; ``unbounded`` is a further allowed value meaning "no limit"."""
    ok = isinstance(value, (int, np.integer)) and not isinstance(value, bool)
    ok = ok and (value == unbounded or low is None or value >= low)
    if not ok:
        what = f"an integer >= {low}" if low is not None else "an integer"
        if unbounded is not None:
            what = f"{unbounded} (unbounded) or {what}"
        raise expected(name, what, value)
    return int(value)


def number(value: Any, name: str, *, low: float | None = None, high: float | None = None,
           low_open: bool = False, high_open: bool = False, what: str | None = None) -> float:
    """``value`` as a finite float within the bounds (each optional, either side open)."""
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    ok = ok and math.isfinite(value)
    if ok and low is not None:
        ok = value > low if low_open else value >= low
    if ok and high is not None:
        ok = value < high if high_open else value <= high
    if not ok:
        if what is None:
            if low is not None and high is not None:
                what = f"a number in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
            elif low is not None:
                what = f"a finite number {'>' if low_open else '>='} {low:g}"
            elif high is not None:
                what = f"a finite number {'<' if high_open else '<='} {high:g}"
            else:
                what = "a finite number"
        raise expected(name, what, value)
    return float(value)
