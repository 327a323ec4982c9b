"""Scenes with little or nothing to render: no lights (black in every estimator, with one warning), a
camera inside a closed mesh (black with the light outside; the analytic radiance with a point light
inside a diffuse sphere), no shapes and a single degenerate triangle (clear SceneErrors)."""
from __future__ import annotations

import copy

import numpy as np
import pytest

import pathspace as ps
from conftest import scene_dict

NO_LIGHTS = "the scene has no lights: the image is black"
ESTIMATORS = ("pt", "lt", "bdpt")


@pytest.mark.parametrize("estimator", ESTIMATORS)
def test_scene_without_lights_renders_black_with_one_warning(estimator):
    data = scene_dict("cornell-box", (8, 8))
    assert [shape.pop("emitter", None) for shape in data["shapes"]].count(None) == len(data["shapes"]) - 1
    result = ps.render(ps.scene_from_dict(data), estimator, spp=2, seed=1)
    assert np.all(result.image == 0) and np.all(result.variance == 0)
    assert result.stats["warnings"].count(NO_LIGHTS) == 1 and result.film.passes == 2


def test_scenes_with_lights_have_no_such_warning():
    result = ps.render(ps.scene_from_dict(scene_dict("cornell-box", (8, 8))), "pt", spp=1)
    assert NO_LIGHTS not in result.stats["warnings"] and result.image.max() > 0


def inside(shape: dict, lights: list[dict], reflectance: float = 0.5) -> dict:
    """A scene whose pinhole camera sits at the origin, inside ``shape`` (centred there), looking along +z."""
    return {"camera": {"position": [0, 0, 0], "look_at": [0, 0, 1], "fov": 60, "resolution": [16, 16]},
            "materials": {"grey": {"type": "diffuse", "reflectance": [reflectance] * 3}},
            "shapes": [dict(shape, material="grey")], "lights": lights}


@pytest.mark.parametrize("estimator", ESTIMATORS)
def test_camera_inside_a_closed_cube_sees_no_light_from_outside(estimator):
    data = inside({"type": "box", "size": [2, 2, 2]}, [{"type": "point", "position": [0, 0, 5], "intensity": [9] * 3}])
    data["shapes"].append({"type": "quad", "corner": [-1, 3, -1], "edge_u": [2, 0, 0], "edge_v": [0, 0, 2],
                           "material": "grey", "emitter": {"radiance": [5, 5, 5], "two_sided": True}})
    result = ps.render(ps.scene_from_dict(data), estimator, spp=4, seed=2)
    assert np.all(result.image == 0) and result.stats["warnings"] == [] and result.stats["nonfinite"] == 0


@pytest.mark.parametrize("estimator", ESTIMATORS)
def test_point_light_inside_a_diffuse_sphere_gives_the_analytic_radiance(estimator):
    """A point light of intensity I at the centre of a closed sphere of radius R and albedo rho: by
    symmetry the radiosity B is uniform, and B = rho (I / R^2 + B) (a sphere's inside sees itself whole),
    so every pixel sees L = B / pi = rho I / ((1 - rho) pi R^2) = 1 for rho = 1/2, I = pi, R = 1."""
    sphere = {"type": "sphere", "radius": 1.0, "subdivisions": 5}  # faces within 1e-4 of the sphere
    data = inside(sphere, [{"type": "point", "position": [0, 0, 0], "intensity": [np.pi] * 3}])
    result = ps.render(ps.scene_from_dict(data), estimator, spp=64, seed=3)
    mean = result.image.mean()
    standard_error = np.sqrt(result.variance.sum()) / result.variance.size
    assert abs(mean - 1.0) < 4 * standard_error + 2e-3, (mean, standard_error)
    assert result.stats["nonfinite"] == 0


def test_scene_without_shapes_is_a_clear_error():
    """Geometry is required: a scene of only an environment light is refused by name (docs/scene-format.md)."""
    data = inside({"type": "box", "size": [2, 2, 2]}, [{"type": "environment", "radiance": [1, 1, 1]}])
    for shapes in ([], None):
        empty = copy.deepcopy(data)
        if shapes is None:
            del empty["shapes"]
        else:
            empty["shapes"] = shapes
        with pytest.raises(ps.SceneError, match=r"empty.toml: shapes: expected a non-empty array of tables"):
            ps.scene_from_dict(empty, source="empty.toml")


@pytest.mark.parametrize("triangle, drop, message", [
    ([[0, 1, 2]], False, r"1 degenerate \(zero-area\) triangle\(s\), the first is triangle 0"),
    ([[0, 1, 1]], False, r"1 degenerate \(zero-area\) triangle\(s\)"),
    ([[0, 1, 2]], True, r"every triangle is degenerate \(zero area\)"),
])
def test_scene_of_one_degenerate_triangle_is_a_clear_error(triangle, drop, message):
    shape = {"type": "triangles", "vertices": [[0, 0, 2], [1, 0, 2], [2, 0, 2]], "triangles": triangle,
             "drop_degenerate": drop}
    data = inside(shape, [{"type": "point", "position": [0, 1, 0], "intensity": [1, 1, 1]}])
    with pytest.raises(ps.SceneError, match=r"one.toml: shapes\[0\]: " + message):
        ps.scene_from_dict(data, source="one.toml")
