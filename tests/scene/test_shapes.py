"""Shape types: built-in spheres (outward normals, area) and boxes (flipped normals), and mesh files read
through trimesh (OBJ, PLY) with scale, rotation and translation."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

import pathspace as ps
from scene.test_toml_loader import load, scene_with


@pytest.mark.parametrize("suffix", ["obj", "ply"])
def test_mesh_files_through_trimesh(tmp_path, suffix):
    trimesh.creation.box(extents=[1, 2, 3]).export(tmp_path / f"box.{suffix}")
    data = scene_with(shapes__0={"type": "mesh", "file": f"box.{suffix}", "material": "grey",
                                 "transform": {"scale": 2, "rotate": {"axis": [0, 1, 0], "angle": 90},
                                               "translate": [10, 0, 0]}})
    scene = ps.scene_from_dict(data, source="s.toml", base_dir=tmp_path)
    box = scene.mesh.shape == 0
    assert box.sum() == 12
    np.testing.assert_allclose(scene.mesh.area[box].sum(), 4 * 2 * (1 * 2 + 2 * 3 + 1 * 3))
    corners = scene.to_world(scene.mesh.vertices)[np.unique(scene.mesh.indices[box])]
    # Scaled by 2, turned 90 degrees about y (x and z swap), moved to x = 10.
    np.testing.assert_allclose(corners.min(axis=0), [10 - 3, -2, -1], atol=1e-12)
    np.testing.assert_allclose(corners.max(axis=0), [10 + 3, 2, 1], atol=1e-12)


def test_builtin_shapes():
    data = scene_with(shapes__0={"type": "sphere", "center": [1, 2, 3], "radius": 0.5, "subdivisions": 4,
                                 "material": "grey"})
    data["shapes"].append({"type": "box", "center": [0, 0, -5], "size": [1, 2, 4], "material": "grey",
                           "flip_normals": True})
    scene = load(data)
    sphere, box = scene.mesh.shape == 0, scene.mesh.shape == 2
    # An inscribed icosphere of 5120 faces has 99.8% of the sphere's area.
    assert 0.997 < scene.mesh.area[sphere].sum() / (np.pi) < 1.0
    centroids = scene.to_world(scene.mesh.vertices)[scene.mesh.indices[sphere]].mean(axis=1) - [1, 2, 3]
    assert np.all(np.sum(centroids * scene.mesh.normal[:, sphere].T, axis=1) > 0)  # outward
    np.testing.assert_allclose(scene.mesh.area[box].sum(), 2 * (2 + 8 + 4))
    centroids = scene.to_world(scene.mesh.vertices)[scene.mesh.indices[box]].mean(axis=1) - [0, 0, -5]
    assert np.all(np.sum(centroids * scene.mesh.normal[:, box].T, axis=1) < 0)  # flipped: inward

