"""References are rendered once, reused while nothing they depend on changes, and know their own error."""
from __future__ import annotations

import json

import numpy as np

import pathspace as ps
from conftest import CORNELL


def test_cached_until_the_scene_changes(tmp_path):
    small = {"resolution": (16, 16)}
    first = ps.reference(ps.load_scene(CORNELL, **small), spp=16, folder=tmp_path)
    assert not first.cached and first.path.is_file() and first.path.with_suffix(".json").is_file()
    again = ps.reference(ps.load_scene(CORNELL, **small), spp=16, folder=tmp_path)
    assert again.cached and again.path == first.path
    np.testing.assert_array_equal(again.image, first.image)
    changed = ps.reference(ps.load_scene(CORNELL, **small, **{"materials.white.reflectance": [0.5, 0.5, 0.5]}),
                           spp=16, folder=tmp_path)
    assert not changed.cached and changed.path != first.path
    other_spp = ps.reference(ps.load_scene(CORNELL, **small), spp=8, folder=tmp_path)
    assert not other_spp.cached
    metadata = json.loads(first.path.with_suffix(".json").read_text())
    assert metadata["scene"] == ps.load_scene(CORNELL, **small).fingerprint
    assert metadata["spp"] == 16 and metadata["estimator"] == "pt" and metadata["seconds"] > 0
    assert metadata["predicted_relmse_low"] <= metadata["predicted_relmse"] <= metadata["predicted_relmse_high"]


def test_a_changed_mesh_file_changes_the_fingerprint(tmp_path):
    mesh = tmp_path / "tri.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text('[camera]\nposition = [0, 0, 3]\nlook_at = [0, 0, 0]\nfov = 40\nresolution = [4, 4]\n'
                          '[materials.m]\ntype = "diffuse"\nreflectance = [0.5, 0.5, 0.5]\n'
                          '[[shapes]]\ntype = "mesh"\nfile = "tri.obj"\nmaterial = "m"\n')
    before = ps.load_scene(scene_file).fingerprint
    mesh.write_text("v 0 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\n")
    assert ps.load_scene(scene_file).fingerprint != before
