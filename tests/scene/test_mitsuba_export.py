"""pathspace scenes written for Mitsuba 3: export then import is the identity on every scene of scenes/ that
Mitsuba can express (world triangles, materials, lights, camera); what it cannot express is one error; the
PLY files; the command line; and, with Mitsuba installed (slow), Mitsuba 3 renders the exported specular box
as pathspace does."""
from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
import trimesh

import pathspace as ps
from pathspace import SceneError
from pathspace.cli import main
from pathspace.driver import render
from pathspace.scene.mitsuba_export import export_mitsuba, mitsuba_dict, write_ply
from pathspace.scene.mitsuba_xml import MitsubaWarning
from pathspace.validate import compare_estimates
from conftest import ROOT, moved, rotation_about, scene_dict
from scene.test_mitsuba_xml import world_lights
from scene.test_toml_loader import load, scene_with

SCENES = sorted(path.parent.name for path in (ROOT / "scenes").glob("*/scene.toml"))
EXPRESSIBLE = [name for name in SCENES if name != "prism"]


def round_trip(scene, folder):
    """``scene`` exported to Mitsuba XML and read back (warnings of either step ignored)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MitsubaWarning)
        written = export_mitsuba(scene, folder / "scene.xml")
        return written, ps.load_scene(written[0])


def assert_same_scene(a, b):
    """Two scenes with the same world triangles (in order), materials, lights, camera and render settings."""
    world_a, world_b = a.to_world(a.mesh.vertices[a.mesh.indices]), b.to_world(b.mesh.vertices[b.mesh.indices])
    atol = 1e-12 * (1 + np.abs(world_a).max())
    np.testing.assert_allclose(world_b, world_a, rtol=0, atol=atol)
    assert np.array_equal(a.mesh.material, b.mesh.material) and np.array_equal(a.mesh.shape, b.mesh.shape)
    # Mitsuba ids are shared by materials and shapes: a shape named like a material is written as NAME'.
    assert [name.removesuffix("'") if name.removesuffix("'") in a.materials.names else name
            for name in b.shape_names] == a.shape_names
    assert a.materials.names == b.materials.names and a.materials.materials == b.materials.materials
    assert type(a.camera) is type(b.camera)
    for key in ("position", "look_at"):
        np.testing.assert_allclose(b.to_world(getattr(b.camera, key)), a.to_world(getattr(a.camera, key)), rtol=0,
                                   atol=atol)
    for key in ("up", "fov", "fov_axis", "resolution", "lens_radius"):
        assert np.all(getattr(a.camera, key) == getattr(b.camera, key)), key
    assert getattr(a.camera, "focus_distance", None) == getattr(b.camera, "focus_distance", None)
    assert a.render_spp == b.render_spp
    lights_a, lights_b = world_lights(a), world_lights(b)
    assert [type(x) for x in lights_a] == [type(x) for x in lights_b]
    for x, y in zip(lights_a, lights_b):
        for field in dataclasses.fields(x):
            u, v = getattr(x, field.name), getattr(y, field.name)
            if field.name in ("position", "look_at"):
                np.testing.assert_allclose(v, u, rtol=0, atol=atol)
            else:
                assert np.array_equal(u, v) if isinstance(u, np.ndarray) else u == v, field.name


@pytest.mark.parametrize("name", EXPRESSIBLE)
def test_export_then_import_is_the_identity(tmp_path, name):
    scene = ps.load_scene(ROOT / "scenes" / name / "scene.toml")
    written, back = round_trip(scene, tmp_path)
    assert written[0].read_text().startswith('<?xml version="1.0" encoding="utf-8"?>')
    assert all(path.suffix == ".ply" and path.parent.name == "scene-meshes" for path in written[1:])
    assert len(written) - 1 == len(scene.shape_names)
    assert_same_scene(scene, back)


def test_round_trip_far_from_the_origin(tmp_path):
    """Positions are written in world coordinates, whatever the scene's render origin."""
    data = moved(scene_dict("cornell-box-point-light"), rotation_about([1, 2, 3], 40), [3e5, -2e5, 1e5])
    scene = ps.scene_from_dict(data)
    _, back = round_trip(scene, tmp_path)
    assert_same_scene(scene, back)
    np.testing.assert_allclose(back.to_world(back.camera.position), scene.to_world(scene.camera.position), rtol=1e-15)


def test_what_mitsuba_cannot_express_is_one_error(tmp_path):
    with pytest.raises(SceneError) as error:
        export_mitsuba(ps.load_scene(ROOT / "scenes" / "prism" / "scene.toml"), tmp_path / "prism.xml")
    lines = str(error.value).splitlines()
    assert lines[0].endswith("prism/scene.toml: cannot be written as a Mitsuba 3 scene:")
    assert lines[1:] == ["  material 'glass': a dispersive dielectric (Cauchy(a=1.6, b=0.01)); Mitsuba's has one index",
                         "  shape 'strip': a two-sided emitter; Mitsuba's area lights emit on one side"]
    assert not list(tmp_path.iterdir())  # nothing written
    phong = scene_with(materials__grey={"type": "phong", "diffuse": [0.5] * 3, "specular": [0.2] * 3, "exponent": 10})
    with pytest.raises(SceneError, match="material 'grey': Mitsuba 3 has no phong model"):
        export_mitsuba(load(phong), tmp_path / "phong.xml")


def test_spot_lights(tmp_path):
    """A spot light with a hard edge is Mitsuba's spot with beam_width = cutoff_angle; a smooth falloff is not."""
    spot = {"type": "spot", "position": [0, 0, 3], "look_at": [0.5, 0, 0], "intensity": [5, 5, 5],
            "cone_angle": 30, "falloff_start": 30}
    scene = load(scene_with(lights=[spot]))
    _, back = round_trip(scene, tmp_path)
    assert_same_scene(scene, back)
    with pytest.raises(SceneError, match=r"spot light at \[0.0, 0.0, 3.0\]: falloff_start 20 < cone_angle 30"):
        export_mitsuba(load(scene_with(lights=[{**spot, "falloff_start": 20}])), tmp_path / "soft.xml")


def test_ply_files_are_binary_float64_and_exact(tmp_path):
    rng = np.random.default_rng(5)
    vertices, faces = rng.normal(size=(7, 3)) * 1e5, rng.integers(0, 7, size=(4, 3))
    write_ply(tmp_path / "m.ply", vertices, faces)
    data = (tmp_path / "m.ply").read_bytes()
    assert data.startswith(b"ply\nformat binary_little_endian 1.0\n") and b"property double x\n" in data
    mesh = trimesh.load(tmp_path / "m.ply", process=False)
    assert np.array_equal(mesh.vertices, vertices) and np.array_equal(mesh.faces, faces)


def test_command_line_export(tmp_path, capsys):
    out = tmp_path / "out" / "box.xml"
    assert main(["export", "--mitsuba", str(ROOT / "scenes" / "cornell-box-thin-lens" / "scene.toml"), str(out),
                 "--set", "camera.resolution=[32,24]"]) == 0
    printed = capsys.readouterr().out
    assert f"wrote {out} and 8 PLY meshes in {out.parent / 'box-meshes'}" in printed
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MitsubaWarning)
        back = ps.load_scene(out)
    assert back.camera.resolution == (32, 24) and back.camera.lens_radius == 0.08
    assert main(["export", "--mitsuba", str(ROOT / "scenes" / "prism" / "scene.toml"), str(tmp_path / "p.xml")]) == 2
    assert "pathspace export: error: " in capsys.readouterr().err


@pytest.mark.slow
def test_mitsuba_renders_the_exported_specular_box_as_pathspace(tmp_path):
    """Mitsuba 3 (scalar_rgb, path tracer) and pathspace (pt) estimate the same image of the exported
    specular box: Mitsuba's per-pixel variance comes from independent renders with different seeds."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    scene = ps.load_scene(ROOT / "scenes" / "cornell-box-specular" / "scene.toml", resolution=(48, 48))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MitsubaWarning)
        xml = export_mitsuba(scene, tmp_path / "specular.xml")[0]
        from_dict = mi.load_dict(mitsuba_dict(scene, tmp_path / "dict-meshes"))
    mitsuba_scene = mi.load_file(str(xml))
    # The dict and the XML describe the same scene: the same seed gives the same image (up to the float
    # rounding of values parsed from text).
    np.testing.assert_allclose(np.asarray(mi.render(from_dict, spp=4, seed=7)),
                               np.asarray(mi.render(mitsuba_scene, spp=4, seed=7)), rtol=1e-3, atol=1e-6)
    runs, spp = 16, 64
    images = np.stack([np.asarray(mi.render(mitsuba_scene, spp=spp, seed=run), dtype=np.float64)[..., :3]
                       for run in range(runs)])
    mean, variance = images.mean(axis=0), images.var(axis=0, ddof=1) / runs
    ours = render(scene, "pt", spp=runs * spp, seed=11)
    result = compare_estimates(mean, variance, ours.image, ours.variance, block=4, alpha=1e-3)
    print(result)
    assert mean.mean() > 0.05
    assert result.passed, str(result)
