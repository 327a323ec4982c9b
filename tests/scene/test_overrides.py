"""Changing a scene at load time: dotted keys, list indices, shorthands, and errors that name the key."""
from __future__ import annotations

import dataclasses

import pytest

import pathspace as ps
from pathspace.scene.overrides import split_key
from conftest import CORNELL


def test_keys():
    assert split_key("shapes[2].transform.translate") == ["shapes", 2, "transform", "translate"]
    assert split_key("lights.0.intensity") == ["lights", 0, "intensity"]
    with pytest.raises(ps.SceneError, match="expected names separated"):
        split_key("shapes[x]")


def test_overrides_change_the_scene():
    scene = ps.load_scene(CORNELL, resolution=(24, 16), spp=3, **{
        "materials.white.reflectance": (0.25, 0.5, 0.75), "shapes[1].transform.translate": [0, 0.5, 0],
        "camera.fov": 30})
    assert scene.camera.resolution == (24, 16) and scene.camera.fov == 30 and scene.render_spp == 3
    white = scene.materials.materials[scene.materials.names.index("white")]
    assert white.reflectance == (0.25, 0.5, 0.75)
    assert ps.render(scene).stats["spp"] == 3  # the scene's [render] spp is the default


def test_override_errors_name_the_key():
    with pytest.raises(ps.SceneError, match=r"override 'shapes\[99\].material': shapes.99 does not exist"):
        ps.load_scene(CORNELL, **{"shapes[99].material": "white"})
    with pytest.raises(ps.SceneError, match=r"materials.white.reflectance: expected 3 finite numbers in \[0, 1\]"):
        ps.load_scene(CORNELL, **{"materials.white.reflectance": [2, 0, 0]})
    with pytest.raises(ps.SceneError, match="render.spp: expected an integer >= 1"):
        ps.load_scene(CORNELL, spp=0)


def test_render_traversal_chooses_how_rays_are_traced():
    fast = ps.load_scene(CORNELL, **{"render.traversal": "fast"})
    assert fast.traversal == "fast" and not fast.accel.watertight and not fast.emitter_accel.watertight
    assert "fast traversal" in fast.describe()
    default = ps.load_scene(CORNELL)
    assert default.traversal == "watertight" and default.accel.watertight
    assert dataclasses.replace(default, traversal="fast").accel.watertight is False
    with pytest.raises(ps.SceneError, match="render.traversal: .*'watertight', 'fast'.*'quick'"):
        ps.load_scene(CORNELL, **{"render.traversal": "quick"})
    with pytest.raises(ValueError, match="traversal: expected one of watertight, fast, got 'quick'"):
        dataclasses.replace(default, traversal="quick")
