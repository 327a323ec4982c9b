"""One regression test per class of loader bug the scene fuzzer (and the probes beside it) found: each
used to escape as a traceback from inside the parser, NumPy or the renderer, or to give a wrong error,
and is now a SceneError naming the file, the field and what was expected -- or a scene that renders."""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace import SceneError
from conftest import scaled, scene_dict
from scene.test_toml_loader import load, scene_with


def test_deeply_nested_toml_is_not_a_recursion_error(tmp_path):
    # tomllib parses nested arrays and inline tables recursively: RecursionError.
    for value in ("[" * 3000 + "]" * 3000, "{a = " * 3000 + "{}" + "}" * 3000):
        path = tmp_path / "deep.toml"
        path.write_text(f"format = 1\nname = {value}\n")
        with pytest.raises(SceneError, match=r"deep.toml: not a valid TOML file: arrays or tables nested too deeply"):
            ps.load_scene(path)


@pytest.mark.parametrize("spectrum, field", [
    ({"wavelengths": [400, {"a": 1}], "values": [1, 1]}, "wavelengths"),  # TypeError inside NumPy
    ({"wavelengths": [400, 500], "values": ["1", "1"]}, "values"),  # strings NumPy silently converted
    ({"wavelengths": [400, 500], "values": [True, 1]}, "values"),
    ({"wavelengths": [400, 10 ** 400], "values": [1, 1]}, "wavelengths"),  # OverflowError inside NumPy
    ({"wavelengths": [], "values": []}, "wavelengths"),
])
def test_sampled_spectra_of_non_numbers(spectrum, field):
    with pytest.raises(SceneError, match=rf"materials.grey.reflectance.{field}: expected a non-empty list of "
                                         rf"finite numbers"):
        load(scene_with(materials__grey__reflectance=spectrum))


@pytest.mark.parametrize("text", ["v 0 0\nv 1 0\nv 0 1\nf 1 2 3\n", "v 0 0 0\nv 1 0\nv 0.\nf 1 2 3\n"])
def test_mesh_file_with_vertices_of_fewer_coordinates(tmp_path, text):
    # trimesh reads such an OBJ as (N, 2) or (N, 1) vertices: an AxisError inside NumPy followed.
    (tmp_path / "flat.obj").write_text(text)
    data = scene_with(shapes__0={"type": "mesh", "file": "flat.obj", "material": "grey"})
    with pytest.raises(SceneError, match=r"s.toml: shapes\[0\].file: mesh file .*flat.obj has vertices of shape "
                                         r"\(3, [12]\), expected 3 coordinates each"):
        ps.scene_from_dict(data, source="s.toml", base_dir=tmp_path)


@pytest.mark.parametrize("changes, message", [
    # Positions beyond float32's safe range used to become non-finite rays (ValueError from the C extension).
    ({"camera__position": [1e300, 0, 5]}, r"camera.position: expected 3 numbers within \+-1e\+30"),
    ({"camera__look_at": [0, 0, -1e31]}, r"camera.look_at: expected 3 numbers within \+-1e\+30"),
    ({"lights": [{"type": "point", "position": [1e300, 0, 0], "intensity": [1, 1, 1]}]},
     r"lights\[0\].position: expected 3 numbers within \+-1e\+30"),
    ({"lights": [{"type": "spot", "position": [0, 0, 1], "look_at": [0, -1e300, 0], "intensity": [1, 1, 1]}]},
     r"lights\[0\].look_at: expected 3 numbers within \+-1e\+30"),
    ({"render": {"origin": [1e300, 0, 0]}}, r"render.origin: expected 3 numbers within \+-1e\+30"),
    ({"camera__type": "thinlens", "camera__aperture_radius": 1e300},
     r"camera.aperture_radius: expected a number > 0 and <= 1e\+30"),
    ({"camera__type": "thinlens", "camera__aperture_radius": 0.1, "camera__focus_distance": 1e300},
     r"camera.focus_distance: expected a number > 0 and <= 1e\+30"),
    # A field of view whose image area underflows made the camera's importance infinite.
    ({"camera__fov": 1e-300}, r"camera.fov: expected a number >= 1e-06 and < 180, got 1e-300"),
    # A zero direction is named as such (it used to pass or be reported as parallel to the view).
    ({"camera__up": [0, 0, 0]}, r"camera.up: must not be the zero vector"),
    ({"lights": [{"type": "directional", "direction": [0, -0.0, 0], "irradiance": [1, 1, 1]}]},
     r"lights\[0\].direction: must not be the zero vector"),
])
def test_positions_and_angles_out_of_float_range(changes, message):
    with pytest.raises(SceneError, match="test.toml: " + message):
        load(scene_with(**changes))


@pytest.mark.parametrize("estimator", ["pt", "lt", "bdpt"])
def test_directions_with_huge_or_tiny_components_render(estimator):
    # Their length used to overflow (or underflow) when normalised: a zero direction, then invalid rays,
    # or an up vector reported as parallel to the view.
    data = scene_with(camera__up=[1e300, 1e300, 0], camera__resolution=[8, 8],
                      lights=[{"type": "directional", "direction": [1e-300, -1e-300, -5e-300], "irradiance": [1] * 3}])
    scene = load(data)
    np.testing.assert_allclose(scene.camera.up, [1, 1, 0])
    result = ps.render(scene, estimator, spp=1, seed=1)
    assert result.stats["nonfinite"] == 0 and np.all(np.isfinite(result.image)) and result.image.max() > 0


def test_small_scenes_are_not_refused_for_their_camera_and_too_small_ones_are_refused_for_their_size():
    # "look_at must differ from position" compared their distance with an absolute 1e-12.
    scene = ps.scene_from_dict(scaled(scene_dict("cornell-box", (8, 8)), 1e-8))
    assert scene.mesh.triangle_count == 36 and np.ptp(scene.mesh.vertices[:, 0]) == pytest.approx(2e-8, rel=1e-3)
    # Below 1e-8 float32 tracing no longer renders the box right (7% dark at 1e-9): a clear error.
    with pytest.raises(SceneError, match=r"shapes: the geometry spans 3.47e-20 scene units"):
        ps.scene_from_dict(scaled(scene_dict("cornell-box", (8, 8)), 1e-20))


@pytest.mark.parametrize("change", ["scale 1e13", "camera 1e16 away"])
def test_geometry_beyond_float32_reach_around_the_origin_is_refused(change):
    # At 1e13 the box rendered 18% (pt) to 3.2x (bdpt) too bright; a camera 1e16 away collapsed the
    # re-centred triangles to zero area (NaN light power, invalid rays).
    data = scene_dict("cornell-box", (8, 8))
    if change == "scale 1e13":
        data = scaled(data, 1e13)
    else:
        data["camera"].update(position=[0.0, 0.0, 1e16], look_at=[0.0, 0.0, 0.0])
    with pytest.raises(SceneError, match=r"within 1e\+12 of that origin"):
        ps.scene_from_dict(data)


def test_disk_normal_with_huge_components():
    # Its length overflowed: NaN vertices, reported as non-finite coordinates.
    scene = load(scene_with(shapes__0={"type": "disk", "normal": [0, 0, 1e300], "radius": 1, "material": "grey"}))
    disk = scene.mesh.shape == 0
    np.testing.assert_allclose(scene.mesh.normal[:, disk].T, np.tile([0, 0, 1], (64, 1)), atol=1e-6)
