"""Shared fixtures: the repository's scenes and small variants of them."""
from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

import pathspace as ps

ROOT = Path(__file__).resolve().parent.parent
CORNELL = ROOT / "scenes" / "cornell-box" / "scene.toml"


def cornell_dict(resolution=(64, 64)) -> dict:
    """The Cornell box scene file as a dict, with another resolution."""
    data = tomllib.loads(CORNELL.read_text())
    data["camera"]["resolution"] = list(resolution)
    return data


@pytest.fixture(scope="session")
def cornell() -> ps.Scene:
    """The Cornell box at its native 256 x 256."""
    return ps.load_scene(CORNELL)


@pytest.fixture(scope="session")
def cornell_small() -> ps.Scene:
    """The Cornell box at 64 x 64."""
    return ps.scene_from_dict(cornell_dict((64, 64)), source="cornell-64")
