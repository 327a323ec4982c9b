"""Changing a scene description at load time: ``load_scene(path, **{"materials.white.reflectance": v})``.

A key is a path into the scene's table structure: names separated by dots,
list items by ``[i]`` (or ``.i``), e.g. ``camera.fov``,
``materials.white.reflectance``, ``shapes[2].transform.translate``,
``lights[0].intensity``.  Missing tables on the way are created (so
``shapes[0].transform.scale`` works on a shape without a transform); a list
index must exist.  The value replaces what was there (tuples become lists).
Two shorthands: ``resolution=(w, h)`` for ``camera.resolution`` and
``spp=n`` for ``render.spp`` (the scene's default samples per pixel).
The overridden description is then checked like any scene file.
"""
from __future__ import annotations

import copy
import re
from typing import Any

from ..fields import SceneError

__all__ = ["apply_overrides", "split_key"]

SHORTHANDS = {"resolution": "camera.resolution", "spp": "render.spp"}
_PART = re.compile(r"([^.\[\]]+)|\[(\d+)\]")


def split_key(key: str) -> list[str | int]:
    """The parts of a key: table names (str) and list indices (int)."""
    parts: list[str | int] = []
    position = 0
    for match in _PART.finditer(key):
        if match.start() != position and key[position:match.start()] != ".":
            raise SceneError(f"override {key!r}: expected names separated by '.' and indices as [i]")
        name, index = match.groups()
        parts.append(int(index) if index is not None else (int(name) if name.isdigit() else name))
        position = match.end()
    if not parts or position != len(key):
        raise SceneError(f"override {key!r}: expected names separated by '.' and indices as [i]")
    return parts


def _plain(value: Any) -> Any:
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    if isinstance(value, list):
        return [_plain(v) for v in value]
    if hasattr(value, "tolist"):  # NumPy arrays and scalars
        return value.tolist()
    return value


def apply_overrides(data: dict, overrides: dict[str, Any], source: str) -> dict:
    """A copy of the scene description ``data`` with every override applied (see the module docstring)."""
    data = copy.deepcopy(data)
    for key, value in overrides.items():
        if value is None:
            continue
        parts = split_key(SHORTHANDS.get(key, key))
        node: Any = data
        for depth, part in enumerate(parts[:-1]):
            here = ".".join(map(str, parts[:depth + 1]))
            if isinstance(part, int):
                if not isinstance(node, list) or not 0 <= part < len(node):
                    raise SceneError(f"{source}: override {key!r}: {here} does not exist "
                                     f"({len(node) if isinstance(node, list) else 'no'} items)")
                node = node[part]
                continue
            if not isinstance(node, dict):
                raise SceneError(f"{source}: override {key!r}: {here} is not a table")
            node = node.setdefault(part, {} if not isinstance(parts[depth + 1], int) else [])
        last = parts[-1]
        if isinstance(last, int):
            if not isinstance(node, list) or not 0 <= last < len(node):
                raise SceneError(f"{source}: override {key!r}: item {last} does not exist")
        elif not isinstance(node, dict):
            raise SceneError(f"{source}: override {key!r}: the parent of {last!r} is not a table")
        node[last] = _plain(value)
    return data
