"""The TOML scene loader: a base scene loads; errors name the file, the field and the expectation;
degenerate triangles are refused or dropped; missing and malformed files; the repository's scenes load."""
from __future__ import annotations

import copy

import numpy as np
import pytest

import pathspace as ps
from pathspace import SceneError
from conftest import ROOT

BASE = {
    "camera": {"position": [0, 0, 5], "look_at": [0, 0, 0], "fov": 40, "resolution": [16, 12]},
    "materials": {"grey": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}},
    "shapes": [
        {"name": "floor", "type": "quad", "corner": [-1, -1, 0], "edge_u": [2, 0, 0], "edge_v": [0, 2, 0],
         "material": "grey"},
        {"name": "lamp", "type": "quad", "corner": [-0.2, -0.2, 1], "edge_u": [0, 0.4, 0], "edge_v": [0.4, 0, 0],
         "material": "grey", "emitter": {"radiance": [5, 5, 5]}},
    ],
}


def scene_with(**changes):
    data = copy.deepcopy(BASE)
    for path, value in changes.items():
        target = data
        keys = path.split("__")
        for key in keys[:-1]:
            target = target[int(key)] if isinstance(target, list) else target[key]
        last = keys[-1]
        if value is DELETE:
            del target[last]
        elif isinstance(target, list):
            target[int(last)] = value
        else:
            target[last] = value
    return data


DELETE = object()


def load(data, source="test.toml"):
    return ps.scene_from_dict(data, source=source)


def test_base_scene_loads():
    scene = load(BASE)
    assert scene.mesh.triangle_count == 4
    assert scene.lights.count == 2
    np.testing.assert_allclose(scene.lights.area.area.sum(), 0.16)
    # The lamp's normal is edge_u x edge_v = (0, 0.4, 0) x (0.4, 0, 0) = -z: it shines down.
    np.testing.assert_allclose(scene.mesh.normal[:, scene.lights.area.triangles].T, [[0, 0, -1]] * 2, atol=1e-7)
    assert scene.camera.resolution == (16, 12)


@pytest.mark.parametrize("changes, message", [
    ({"shapes__0__material": "gold"}, r"test.toml: shapes\[0\] \('floor'\).material: unknown material 'gold' "
                                      r"\(defined: grey\)"),
    ({"shapes__1__emitter": {"radiance": [1, 2]}}, r"shapes\[1\] \('lamp'\).emitter.radiance: expected 3 finite "
                                                   r"numbers >= 0, got \[1, 2\]"),
    ({"shapes__1__emitter": {"radiance": [1, -2, 0]}}, r"emitter.radiance: expected 3 finite numbers >= 0"),
    ({"shapes__1__emitter": {"radiance": [float("nan"), 1, 1]}}, r"emitter.radiance: expected 3 finite numbers"),
    ({"shapes__1__emitter": {"radiance": [0, 0, 0]}}, r"emitter.radiance: expected at least one positive"),
    ({"shapes__1__emitter": {"radiance": [1, 1, 1], "twosided": True}}, r"emitter: unknown field\(s\) 'twosided'"),
    ({"camera__position": [0, 0]}, r"camera.position: expected 3 finite numbers, got \[0, 0\]"),
    ({"camera__look_at": [0, 0, 5]}, r"camera.look_at: must differ from position"),
    ({"camera__up": [0, 0, 2]}, r"camera.up: must not be zero or parallel to the viewing direction"),
    ({"camera__fov": 180}, r"camera.fov: expected a number >= 1e-06 and < 180, got 180"),
    ({"camera__fov": float("nan")}, r"camera.fov: expected a number >= 1e-06 and < 180, got nan"),
    ({"camera__resolution": [0, 10]}, r"camera.resolution: expected 2 integers >= 1"),
    ({"camera__fov_axis": "diagonal"}, r"camera.fov_axis: expected one of 'x', 'y', 'smaller', 'larger'"),
    ({"camera__focal": 1}, r"camera: unknown field\(s\) 'focal'"),
    ({"camera": DELETE}, r"test.toml: camera: required field is missing"),
    ({"materials__grey__reflectance": [0.5, 1.5, 0.5]}, r"materials.grey.reflectance: expected 3 finite numbers in \[0, 1\]"),
    ({"materials__grey__type": "plastic"}, r"materials.grey.type: expected one of 'diffuse', 'phong', .*, got "
                                           r"'plastic'"),
    ({"materials__grey": {"type": "phong", "diffuse": [0.6] * 3, "specular": [0.5] * 3, "exponent": 10}},
     r"materials.grey.specular: diffuse \+ specular must not exceed 1 per channel"),
    ({"materials__grey": {"type": "conductor", "eta": [0.2] * 3, "k": [3] * 3, "alpha": 0}},
     r"materials.grey.alpha: expected a GGX roughness in \[0.0001, 1\], got 0"),
    ({"materials__grey": {"type": "dielectric", "ior": -1}}, r"materials.grey.ior: expected a number > 0"),
    ({"materials__grey": {"type": "dielectric", "ior": {}}}, r"materials.grey.ior: expected a number > 0 or a "
                                                             r"dispersion law"),
    ({"materials__grey": {"type": "dielectric", "ior": {"cauchy": [1.0, -0.5]}}},
     r"materials.grey.ior.cauchy: a = 1.0, b = -0.5 give an index <= 0 within 360-830 nm"),
    ({"lights": [{"type": "environment", "radiance": [1, 1, 1]}] * 2},
     r"test.toml: lights: at most one environment light is supported, got 2"),
    ({"lights": [{"type": "point", "position": [0, 0, 1]}]}, r"lights\[0\].intensity: required field is missing"),
    ({"lights": [{"type": "spot", "position": [0, 0, 1], "look_at": [0, 0, 1], "intensity": [1, 1, 1]}]},
     r"lights\[0\].look_at: must differ from position"),
    ({"lights": [{"type": "directional", "direction": [0, 0, 0], "irradiance": [1, 1, 1]}]},
     r"lights\[0\].direction: must not be the zero vector"),
    ({"lights": [{"type": "environment", "radiance": [0, 0, 0]}]},
     r"lights\[0\].radiance: expected at least one positive component"),
    ({"lights": [{"type": "laser"}]}, r"lights\[0\].type: expected one of 'point', 'spot'"),
    ({"camera__type": "thinlens"}, r"camera.aperture_radius: required field is missing"),
    ({"camera__type": "thinlens", "camera__aperture_radius": 0.1, "camera__focus_distance": -2},
     r"camera.focus_distance: expected a number > 0"),
    ({"shapes__0": {"type": "sphere", "radius": 1, "subdivisions": 40, "material": "grey"}},
     r"shapes\[0\].subdivisions: expected an integer >= 0 and <= 8"),
    ({"camera__resolution": [2 ** 70, 10]}, r"camera.resolution: expected 2 integers >= 1"),
    ({"camera__fov": 2 ** 1100}, r"camera.fov: expected a number >= 1e-06 and < 180"),
    ({"shapes__0": {"type": "box", "size": [1e39, 1, 1], "material": "grey"}},
     r"shapes\[0\]: vertex coordinates must be finite and within"),
    ({"shapes": []}, r"shapes: expected a non-empty array of tables"),
    ({"shapes__0__type": "cone"}, r"shapes\[0\] \('floor'\).type: expected one of 'triangles', 'mesh', 'quad'"),
    ({"shapes__0__edge_v": [4, 0, 0]}, r"shapes\[0\] \('floor'\): 2 degenerate \(zero-area\) triangle\(s\)"),
    ({"shapes__1__edge_v": [0, 0.8, 0], "shapes__1__drop_degenerate": True},
     r"shapes\[1\] \('lamp'\): every triangle is degenerate \(zero area\)"),
    ({"shapes__0__size": [1, 1, 1]}, r"shapes\[0\] \('floor'\): unknown field\(s\) 'size'"),
    ({"shapes__0__transform": {"scale": 0}}, r"transform.scale: expected non-zero scale factors"),
    ({"shapes__0__transform": {"rotate": {"axis": [0, 0, 0], "angle": 10}}}, r"rotate.axis: expected a non-zero"),
    ({"format": 2}, r"test.toml: format: this pathspace reads scene format 1, got 2"),
])
def test_errors_name_file_field_and_expectation(changes, message):
    with pytest.raises(SceneError, match=message):
        load(scene_with(**changes))


def test_zero_area_emitter_is_rejected():
    data = scene_with(shapes__1__edge_v=[0, 0.8, 0])  # collinear edges: zero area
    with pytest.raises(SceneError, match=r"shapes\[1\] \('lamp'\): 2 degenerate \(zero-area\) triangle"):
        load(data)


def test_degenerate_triangles_can_be_dropped():
    data = scene_with(shapes__0={"name": "soup", "type": "triangles", "material": "grey", "drop_degenerate": True,
                                 "vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0]],
                                 "triangles": [[0, 1, 2], [0, 1, 3]]})
    assert load(data).mesh.triangle_count == 3  # 1 kept of the soup + the lamp's 2


def test_files_missing_or_malformed(tmp_path):
    with pytest.raises(SceneError, match=r"nothere.toml: scene file not found"):
        ps.load_scene(tmp_path / "nothere.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[camera\nfov = 3")
    with pytest.raises(SceneError, match=r"bad.toml: not a valid TOML file"):
        ps.load_scene(bad)
    missing_mesh = scene_with(shapes__0={"type": "mesh", "file": "bunny.obj", "material": "grey"})
    with pytest.raises(SceneError, match=r"shapes\[0\].file: mesh file not found: .*bunny.obj"):
        ps.scene_from_dict(missing_mesh, source="s.toml", base_dir=tmp_path)
    (tmp_path / "junk.obj").write_text("this is not a mesh\n")
    junk = scene_with(shapes__0={"type": "mesh", "file": "junk.obj", "material": "grey"})
    with pytest.raises(SceneError, match=r"shapes\[0\].file: (mesh file .*junk.obj contains no triangles|cannot read)"):
        ps.scene_from_dict(junk, source="s.toml", base_dir=tmp_path)


def test_repository_scenes_load():
    for path in sorted((ROOT / "scenes").glob("*/scene.toml")):
        scene = ps.load_scene(path)
        assert scene.lights.count > 0, path

