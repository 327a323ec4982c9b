"""Typed, validated reads of one table of a scene description, and the error they raise.

Every model (camera, material, light, shape) reads its own parameters
through a :class:`Fields` reader over its table.  Each read names the field
by its full path, so that every error says which file, which field and what
was expected, e.g.::

    scene.toml: shapes[3].emitter.radiance: expected 3 finite numbers >= 0, got [1, -2, 0]

Unknown keys are errors too (a misspelt field must not be silently ignored).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np

from .spectra import Blackbody, Colour, Illuminant, SampledSpectrum

__all__ = ["Fields", "SceneError", "MAX_COORDINATE"]


class SceneError(ValueError):
    """A scene file or scene description is invalid.

    The message names the file, the field (as a path such as
    ``shapes[2].emitter.radiance``) and what was expected.
    """

_MISSING = object()
# Integers beyond this are rejected before NumPy sees them (it cannot hold them in 64 bits).
MAX_INTEGER = 2 ** 53
# Geometry is traced in float32: positions and lengths must stay well inside its range (3.4e38), so that
# differences and sums of them stay finite too.
MAX_COORDINATE = 1e30


def _finite_number(value: Any, integer: bool = False) -> bool:
    """Whether a value read from a scene is a finite number (an integer if ``integer``) that NumPy can hold:
    not a bool, and an integer no larger than MAX_INTEGER."""
    if isinstance(value, bool) or not isinstance(value, int if integer else (int, float)):
        return False
    return abs(value) <= MAX_INTEGER if isinstance(value, int) else math.isfinite(value)


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


class Fields:
    """Reader over one table (a dict) at a given path of a scene file."""

    REQUIRED = _MISSING  # the default that makes a field required

    def __init__(self, table: Any, path: str, source: str, base: str | Path | None = None,
                 files: list[Path] | None = None) -> None:
        self.source = source
        self.path = path
        self.base = Path(base) if base is not None else Path.cwd()  # where relative file names start
        self.files = files if files is not None else []  # every file read, shared by all readers of a scene
        if not isinstance(table, dict):
            raise self.error(f"expected a table, got {_show(table)}", field=None)
        self.table = table
        self.used: set[str] = set()

    def name(self, field: str | None) -> str:
        """Full path of a field of this table."""
        if field is None:
            return self.path or "(top level)"
        return f"{self.path}.{field}" if self.path else field

    def error(self, message: str, field: str | None) -> SceneError:
        """A SceneError naming the file and the field."""
        return SceneError(f"{self.source}: {self.name(field)}: {message}")

    def has(self, field: str) -> bool:
        """Whether the field is present."""
        return field in self.table

    def _get(self, field: str, default: Any) -> Any:
        self.used.add(field)
        if field in self.table:
            return self.table[field]
        if default is _MISSING:
            raise self.error("required field is missing", field)
        return default

    def raw(self, field: str, default: Any = _MISSING) -> Any:
        """The value of a field without type checks (marks it as known)."""
        return self._get(field, default)

    def sub(self, field: str, default: Any = _MISSING) -> "Fields | None":
        """The sub-table ``field`` as a Fields reader (None if absent and a default was given)."""
        value = self._get(field, default)
        if value is None:
            return None
        return self.reader(value, self.name(field))

    def reader(self, table: Any, path: str) -> "Fields":
        """A reader of another table of the same scene (e.g. an item of an array of tables) at ``path``."""
        return Fields(table, path, self.source, self.base, self.files)

    def string(self, field: str, default: Any = _MISSING, choices: Iterable[str] | None = None) -> str:
        """A string, optionally one of ``choices``."""
        value = self._get(field, default)
        if not isinstance(value, str):
            raise self.error(f"expected a string, got {_show(value)}", field)
        if choices is not None:
            options = list(choices)
            if value not in options:
                raise self.error(f"expected one of {', '.join(map(repr, options))}, got {value!r}", field)
        return value

    def boolean(self, field: str, default: Any = _MISSING) -> bool:
        """true or false."""
        value = self._get(field, default)
        if not isinstance(value, bool):
            raise self.error(f"expected true or false, got {_show(value)}", field)
        return value

    def number(self, field: str, default: Any = _MISSING, *, low: float | None = None, high: float | None = None,
               low_open: bool = False, high_open: bool = False) -> float:
        """A finite number within [low, high] (bounds optional, either side may be open)."""
        value = self._get(field, default)
        self._check_number(value, field, low, high, low_open, high_open, what="a number")
        return float(value)

    def integer(self, field: str, default: Any = _MISSING, *, low: int | None = None,
                high: int | None = None) -> int:
        """An integer within [low, high] (each bound optional)."""
        value = self._get(field, default)
        if (isinstance(value, bool) or not isinstance(value, int) or (low is not None and value < low)
                or (high is not None and value > high) or abs(value) > MAX_INTEGER):
            bound = " and ".join(b for b in (f">= {low}" if low is not None else "",
                                             f"<= {high}" if high is not None else "") if b)
            raise self.error(f"expected an integer{' ' + bound if bound else ''}, got {_show(value)}", field)
        return value

    def vector(self, field: str, length: int, default: Any = _MISSING, *, low: float | None = None,
               integer: bool = False) -> np.ndarray:
        """A list of ``length`` finite numbers (each >= low if given), as float64 (or int64 if integer)."""
        value = self._get(field, default)
        kind = "integers" if integer else "finite numbers"
        bound = f" >= {low:g}" if low is not None else ""
        expected = f"expected {length} {kind}{bound}, got {_show(value)}"
        if not isinstance(value, (list, tuple)) or len(value) != length:
            raise self.error(expected, field)
        for item in value:
            if isinstance(item, bool) or not isinstance(item, (int, float)):
                raise self.error(expected, field)
            if integer and not isinstance(item, int):
                raise self.error(expected, field)
            if isinstance(item, int) and abs(item) > MAX_INTEGER:
                raise self.error(expected + f" (integers must not exceed {MAX_INTEGER} in magnitude)", field)
            if not math.isfinite(item) or (low is not None and item < low):
                raise self.error(expected, field)
        return np.array(value, dtype=np.int64 if integer else np.float64)

    def point(self, field: str, default: Any = _MISSING) -> np.ndarray:
        """A position: 3 finite numbers within +-MAX_COORDINATE (geometry is traced in float32)."""
        value = self.vector(field, 3, default)
        if np.abs(value).max() > MAX_COORDINATE:
            raise self.error(f"expected 3 numbers within +-{MAX_COORDINATE:g} (positions are traced in float32), "
                             f"got {value.tolist()}", field)
        return value

    def direction(self, field: str, default: Any = _MISSING) -> np.ndarray:
        """A direction: 3 finite numbers, not all zero, scaled so that the largest magnitude is 1 (so that its
        length neither overflows nor underflows)."""
        value = self.vector(field, 3, default)
        largest = np.abs(value).max()
        if largest == 0:
            raise self.error("must not be the zero vector", field)
        return value / largest

    def numbers(self, field: str, default: Any = _MISSING) -> np.ndarray:
        """A non-empty list of finite numbers, as a float64 array."""
        value = self._get(field, default)
        if not (isinstance(value, (list, tuple)) and value and all(_finite_number(x) for x in value)):
            raise self.error(f"expected a non-empty list of finite numbers, got {_show(value)}", field)
        return np.array(value, dtype=np.float64)

    def array(self, field: str, columns: int, *, integer: bool = False) -> np.ndarray:
        """A non-empty list of rows of ``columns`` numbers, as an (M, columns) array."""
        value = self._get(field, _MISSING)
        kind = "integers" if integer else "finite numbers"
        expected = f"expected a non-empty list of rows of {columns} {kind}"
        if not isinstance(value, list) or not value:
            raise self.error(f"{expected}, got {_show(value)}", field)
        for i, row in enumerate(value):
            if not (isinstance(row, (list, tuple)) and len(row) == columns
                    and all(_finite_number(x, integer) for x in row)):
                raise self.error(f"{expected}; row {i} is {_show(row)}", field)
        return np.array(value, dtype=np.int64 if integer else np.float64)

    def file(self, field: str, what: str) -> Path:
        """The name of an existing ``what`` file ("mesh", "spectrum"), relative to the scene file's folder."""
        name = self.string(field)
        path = Path(name) if Path(name).is_absolute() else self.base / name
        if not path.is_file():
            raise self.error(f"{what} file not found: {path}", field)
        self.files.append(path)
        return path

    def colour(self, field: str, default: Any = _MISSING) -> Colour:
        """An RGB triple of numbers >= 0, or a spectrum table (see docs/scene-format.md)."""
        value = self.raw(field, default)
        if isinstance(value, dict):
            return self._spectrum(self.sub(field))
        if not isinstance(value, (list, tuple)):
            raise self.error(f"expected 3 numbers (RGB) or a spectrum table, got {_show(value)}", field)
        return tuple(float(x) for x in self.vector(field, 3, default, low=0.0))

    def _spectrum(self, fields: "Fields") -> Colour:
        forms = [key for key in ("wavelengths", "file", "blackbody", "illuminant") if fields.has(key)]
        if len(forms) != 1:
            raise fields.error("expected exactly one of: wavelengths (with values), file, blackbody, illuminant", None)
        scale = fields.number("scale", 1.0, low=0.0)
        form = forms[0]
        if form == "wavelengths":
            wavelengths, values = fields.numbers("wavelengths"), fields.numbers("values")
            spectrum = fields.build(lambda: SampledSpectrum(tuple(wavelengths.tolist()), tuple(values.tolist()), scale))
        elif form == "file":
            path = fields.file("file", "spectrum")
            spectrum = fields.build(lambda: SampledSpectrum.from_csv(path, scale))
        elif form == "blackbody":
            spectrum = fields.build(lambda: Blackbody(fields.number("blackbody", low=0.0, low_open=True), scale))
        else:
            spectrum = fields.build(lambda: Illuminant(fields.string("illuminant"), scale))
            fields.build(spectrum.on_grid)  # an unknown name fails here, with the names colour-science knows
        fields.finish()
        return spectrum

    def build(self, make: Callable[[], Any]) -> Any:
        """``make()``, with a ValueError of the form "field: message" turned into a SceneError naming the field."""
        try:
            return make()
        except SceneError:
            raise
        except ValueError as error:
            field, _, message = str(error).partition(": ")
            raise self.error(message or str(error), field if message else None) from None

    def finish(self) -> None:
        """Raise for any key of the table that no read asked for (a misspelt or unsupported field)."""
        unknown = sorted(set(self.table) - self.used)
        if unknown:
            known = ", ".join(sorted(self.used)) or "none"
            raise self.error(f"unknown field(s) {', '.join(map(repr, unknown))} (known fields: {known})",
                             field=None)

    def _check_number(self, value, field, low, high, low_open, high_open, what):
        ok = _finite_number(value)
        if ok and low is not None:
            ok = value > low if low_open else value >= low
        if ok and high is not None:
            ok = value < high if high_open else value <= high
        if not ok:
            parts = []
            if low is not None:
                parts.append(f"{'>' if low_open else '>='} {low:g}")
            if high is not None:
                parts.append(f"{'<' if high_open else '<='} {high:g}")
            bound = (" " + " and ".join(parts)) if parts else ""
            raise self.error(f"expected {what}{bound}, got {_show(value)}", field)
