"""Furnace helpers (pathspace.validate.furnace): the analytic radiance Le / (1 - rho), refused where it is
infinite, and the furnace scene: a closed cube, every wall emitting and reflecting inward, seen from its
centre (the scene of scenes/furnace, whose answer the estimators are checked against)."""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace.validate import furnace_radiance, furnace_scene
from conftest import scene_dict


def test_furnace_radiance():
    assert furnace_radiance(0.0, 2.0) == 2.0
    assert furnace_radiance(0.5, 1.0) == pytest.approx(2.0)
    assert furnace_radiance(0.99, 3.0) == pytest.approx(300.0)
    for albedo in (1.0, -0.1, 1.5):
        with pytest.raises(ValueError, match="albedo must lie in"):
            furnace_radiance(albedo, 1.0)


def test_furnace_scene_is_a_closed_emitting_cube_seen_from_inside():
    scene = furnace_scene(0.8, emission=2.0, resolution=(8, 6), size=3.0)
    mesh, lights = scene.mesh, scene.lights
    assert mesh.triangle_count == 12 and lights.area.count == 12   # every wall emits
    np.testing.assert_allclose(mesh.area.sum(), 6 * 3.0 ** 2)
    np.testing.assert_allclose(mesh.vertices.min(axis=0), -1.5)
    np.testing.assert_allclose(mesh.vertices.max(axis=0), 1.5)
    # Normals point inward, toward the camera at the centre.
    centroids = mesh.vertices[mesh.indices].mean(axis=1)
    assert np.all(np.sum(centroids * mesh.normal.T, axis=1) < 0)
    np.testing.assert_allclose(scene.camera.position, 0.0)
    assert scene.camera.resolution == (8, 6)
    np.testing.assert_allclose(scene.materials.albedo, 0.8)
    np.testing.assert_allclose(lights.power, np.pi * mesh.area[lights.area.triangles] * 2.0)


def test_the_repository_furnace_is_the_same_scene():
    """scenes/furnace (albedo 0.9) and furnace_scene(0.9) describe the same geometry, camera and light."""
    a, b = ps.scene_from_dict(scene_dict("furnace", (16, 16))), furnace_scene(0.9, resolution=(16, 16))
    np.testing.assert_array_equal(a.mesh.vertices, b.mesh.vertices)
    np.testing.assert_array_equal(a.mesh.indices, b.mesh.indices)
    np.testing.assert_array_equal(a.lights.power, b.lights.power)
    np.testing.assert_array_equal(a.materials.albedo, b.materials.albedo)
    np.testing.assert_array_equal(a.camera.position, b.camera.position)
