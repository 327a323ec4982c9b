"""Mitsuba scene XML read as pathspace scenes: Mitsuba 3's Cornell box written as XML is scenes/cornell-box; 0.6
and 3 syntax read alike; transforms, parameters, lights, spheres and disks, mirroring transforms; what pathspace
cannot render is an error naming element and line, harmless differences one warning; malformed files are clear
errors.  Also the TOML features the Mitsuba reader needs: a transform matrix and disks."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import trimesh

import pathspace as ps
from pathspace import SceneError
from pathspace.driver import render
from pathspace.scene.mitsuba_xml import NAMED_IORS, MitsubaWarning, convert_mitsuba, load_mitsuba
from conftest import ROOT, agree
from scene.test_toml_loader import load, scene_with

CORNELL_XML = ROOT / "scenes" / "cornell-box" / "cornell-box-mitsuba3.xml"
CORNELL_TOML = ROOT / "scenes" / "cornell-box" / "scene.toml"

SENSOR = """<sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="12"/>
            <rfilter type="box"/></film>
    </sensor>"""
FLOOR = """<shape type="rectangle" id="floor"><bsdf type="twosided"><bsdf type="diffuse"/></bsdf></shape>"""


def write(tmp_path, body, version="3.0.0", sensor=SENSOR, name="scene.xml"):
    """A scene file of ``body`` with a default sensor; returns its path."""
    path = tmp_path / name
    path.write_text(f'<?xml version="1.0"?>\n<scene version="{version}">\n    {sensor}\n    {body}\n</scene>\n')
    return path


def line_of(path, needle: str) -> int:
    """The line (from 1) of the first occurrence of ``needle`` in a file."""
    return next(i for i, line in enumerate(path.read_text().splitlines(), 1) if needle in line)


def load_xml(path, **kwargs):
    """The scene and the lines of the MitsubaWarning it gave (none: [])."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", MitsubaWarning)
        scene = load_mitsuba(path, **kwargs)
    messages = [str(w.message) for w in caught if issubclass(w.category, MitsubaWarning)]
    assert len(messages) <= 1  # reported once per file
    return scene, messages[0].splitlines()[1:] if messages else []


def shape_triangles(scene, index):
    """World positions (F, 3, 3) of one shape's triangles."""
    return scene.to_world(scene.mesh.vertices[scene.mesh.indices[scene.mesh.shape == index]])


def planes(triangles, tol):
    """The planes (unit normal, offset) a triangle soup lies in, with the area on each (greedy, within tol)."""
    cross = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    unit = cross / np.linalg.norm(cross, axis=1)[:, None]
    found = []
    for plane, area in zip(np.c_[unit, np.sum(unit * triangles[:, 0], axis=1)], np.linalg.norm(cross, axis=1) / 2):
        match = next((entry for entry in found if np.allclose(entry[0], plane, atol=tol)), None)
        if match is None:
            found.append([plane, area])
        else:
            match[1] += area
    return found


def assert_same_surface(a, b, tol):
    """Two triangle soups cover the same oriented polygons (triangulations may differ): the same corners,
    the same planes with the same area in each (to a relative 4 tol: float32 rounding moves corners by tol)."""
    corners_a, corners_b = np.unique(a.reshape(-1, 3), axis=0), np.unique(b.reshape(-1, 3), axis=0)
    for x, y in ((corners_a, corners_b), (corners_b, corners_a)):
        assert np.abs(x[:, None] - y[None]).max(axis=2).min(axis=1).max() < tol
    planes_a, planes_b = planes(a, tol), planes(b, tol)
    assert len(planes_a) == len(planes_b)
    for plane, area in planes_a:
        assert any(np.allclose(plane, other, atol=tol) and abs(area - other_area) < 4 * tol * area
                   for other, other_area in planes_b)


def world_lights(scene):
    """The scene's lights with positions in world coordinates."""
    return [light.translated(scene.origin) for light in scene.lights.lights]


def test_cornell_box_xml_is_the_toml_scene():
    """Mitsuba 3's Cornell box as XML builds the scene of scenes/cornell-box (whose triangles are Mitsuba's,
    rounded to float32): camera, materials and lights exactly, every shape's surface to float32 precision."""
    xml, messages = load_xml(CORNELL_XML)
    toml = ps.load_scene(CORNELL_TOML)
    for key in ("position", "look_at"):
        np.testing.assert_array_equal(xml.to_world(getattr(xml.camera, key)), toml.to_world(getattr(toml.camera, key)))
    assert repr(xml.camera) == repr(toml.camera)
    assert xml.materials.names == toml.materials.names == ["white", "green", "red"]
    assert xml.materials.materials == toml.materials.materials
    assert xml.shape_names == toml.shape_names
    assert np.array_equal(xml.mesh.material, toml.mesh.material)
    for index in range(len(toml.shape_names)):
        assert_same_surface(shape_triangles(xml, index), shape_triangles(toml, index), tol=2e-7)
    [light], [reference] = xml.lights.lights, toml.lights.lights
    assert (light.radiance, light.two_sided) == (reference.radiance, reference.two_sided)
    assert light.radiance == (18.387, 13.9873, 6.75357) and not light.two_sided
    np.testing.assert_array_equal(light.triangles, reference.triangles)
    np.testing.assert_allclose(xml.lights.power, toml.lights.power, rtol=1e-6)
    assert xml.render_spp == 64
    # What pathspace ignores or does differently is reported once, element by element, with lines.
    for needle, text in [('<rfilter type="gaussian"/>', "box filter"), ('name="pixel_format"', "output format"),
                         ('name="component_format"', "output format"), ('name="focus_distance"', "no focal plane"),
                         ('<integrator type="path">', "max_depth=8")]:
        line = line_of(CORNELL_XML, needle)
        assert any(m.startswith(f"  line {line}, ") and text in m for m in messages), (needle, messages)
    assert "front side only" in messages[-1] and all(f"'{name}'" in messages[-1] for name in ("white", "green", "red"))
    assert len(messages) == 6


def test_cornell_box_xml_renders_as_the_toml_scene():
    """Independent renders of the two files estimate the same image (block-wise z-test)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MitsubaWarning)
        xml = ps.load_scene(CORNELL_XML, resolution=(64, 64))
    toml = ps.load_scene(CORNELL_TOML, resolution=(64, 64))
    a, b = render(xml, "pt", spp=16, seed=1), render(toml, "pt", spp=16, seed=2)
    assert a.image.mean() > 0.1
    ok, report = agree(a, b)
    assert ok, report


SYNTAX = """<sensor type="thinlens">
        <float name="fov" value="30"/><string name="{fov_axis}" value="y"/>
        <float name="{aperture_radius}" value="0.1"/><float name="{focus_distance}" value="4"/>
        <float name="{near_clip}" value="0.5"/><float name="{far_clip}" value="50"/>
        <transform name="{to_world}"><lookat origin="1, 2, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="{sample_count}" value="8"/></sampler>
        <film type="hdrfilm"><integer name="width" value="20"/><integer name="height" value="10"/>
            <rfilter type="box"/></film>
    </sensor>
    <bsdf type="dielectric" id="glass">
        <string name="{int_ior}" value="water"/><float name="{ext_ior}" value="1"/></bsdf>
    <shape type="cube"><ref id="glass"/>
        <transform name="{to_world}"><rotate {axis} angle="30"/><translate x="0" y="0.5" z="0"/></transform></shape>
    <shape type="rectangle"><bsdf type="twosided">
        <bsdf type="diffuse"><{colour} name="{reflectance}" value="{value}"/></bsdf></bsdf>
        <emitter type="area"><spectrum name="radiance" value="400:1, 500:2, 600:3"/></emitter></shape>
    <emitter type="spot"><float name="{cutoff_angle}" value="25"/><float name="{beam_width}" value="25"/>
        <transform name="{to_world}"><lookat origin="0, 3, 0" target="0, 0, 0" up="1, 0, 0"/></transform>
        <rgb name="intensity" value="5"/></emitter>"""
MITSUBA_06 = dict(fov_axis="fovAxis", aperture_radius="apertureRadius", focus_distance="focusDistance",
                  near_clip="nearClip", far_clip="farClip", to_world="toWorld", sample_count="sampleCount",
                  int_ior="intIOR", ext_ior="extIOR", axis='y="1"', colour="srgb", reflectance="diffuseReflectance",
                  value="#ff8000", cutoff_angle="cutoffAngle", beam_width="beamWidth")


def test_mitsuba_06_syntax_reads_as_mitsuba_3(tmp_path):
    """The same scene in 0.6 syntax (camelCase names, rotate x/y/z, srgb hex colours) and in 3 syntax."""
    from pathspace._colour import colour

    decoded = colour.cctf_decoding(np.array([0xff, 0x80, 0x00]) / 255, function="sRGB")
    mitsuba_3 = {key: key for key in MITSUBA_06} | dict(axis='value="0, 1, 0"', colour="rgb",
                                                        value=", ".join(repr(float(v)) for v in decoded))
    v06 = write(tmp_path, "", version="0.6.0", sensor=SYNTAX.format(**MITSUBA_06), name="v06.xml")
    v3 = write(tmp_path, "", sensor=SYNTAX.format(**mitsuba_3), name="v3.xml")
    a, b = convert_mitsuba(v06).data, convert_mitsuba(v3).data
    assert {**a, "name": "v3"} == b
    assert b["camera"] == {"type": "thinlens", "position": [1.0, 2.0, 5.0], "look_at": [0.0, 0.0, 0.0],
                           "up": [0.0, 1.0, 0.0], "fov": 30.0, "fov_axis": "y", "resolution": [20, 10],
                           "aperture_radius": 0.1, "focus_distance": 4.0}
    assert b["render"] == {"spp": 8}
    assert b["materials"]["glass"] == {"type": "dielectric", "ior": 1.333}
    needle = '<bsdf type="diffuse">'
    np.testing.assert_allclose(b["materials"][f"diffuse@{line_of(v3, needle)}"]["reflectance"],
                               [1.0, 0.2158605, 0.0], atol=1e-6)
    assert b["shapes"][1]["emitter"] == {"radiance": {"wavelengths": [400.0, 500.0, 600.0],
                                                      "values": [1.0, 2.0, 3.0]}}
    assert b["lights"] == [{"type": "spot", "position": [0.0, 3.0, 0.0], "look_at": [0.0, 0.0, 0.0],
                            "intensity": [5.0, 5.0, 5.0], "cone_angle": 25.0, "falloff_start": 25.0}]
    scene, _ = load_xml(v3)
    assert isinstance(scene.camera, ps.camera.ThinLensCamera) and scene.camera.focus_distance == 4.0


def test_transforms(tmp_path):
    """Operations apply in the order written (each multiplies from the left); matrix rows are rows; a lookat
    maps local +z to its view direction."""
    path = write(tmp_path, """
    <shape type="rectangle"><transform name="to_world">
        <scale value="2, 1, 1"/><rotate value="0, 0, 1" angle="90"/><translate value="0, 0, 5"/></transform></shape>
    <shape type="rectangle"><transform name="to_world">
        <matrix value="0 -1 0 0  2 0 0 0  0 0 1 5  0 0 0 1"/></transform></shape>
    <shape type="rectangle"><transform name="to_world"><matrix value="0, -1, 0, 0, 0, 2, 1, 0, 0"/></transform></shape>
    <shape type="rectangle"><transform name="to_world">
        <lookat origin="3, 0, 0" target="4, 0, 0" up="0, 0, 1"/></transform></shape>""")
    scene, _ = load_xml(path)
    # (x, y) -> (2x, y) -> (-y, 2x): corners (+-1, +-2) at z = 5, normal +z.
    for index in (0, 1):
        corners = np.unique(shape_triangles(scene, index).reshape(-1, 3), axis=0)
        np.testing.assert_allclose(corners, [[-1, -2, 5], [-1, 2, 5], [1, -2, 5], [1, 2, 5]], atol=1e-12)
        np.testing.assert_allclose(scene.mesh.normal[:, scene.mesh.shape == index].T, [[0, 0, 1]] * 2, atol=1e-7)
    # 3 x 3 rows: (x, y, z) -> (-y, 2z, x): the rectangle lies in the plane y = 0.
    np.testing.assert_allclose(shape_triangles(scene, 2)[..., 1], 0.0, atol=1e-12)
    # The lookat's local +z (the normal) is its direction +x; it sits at x = 3.
    np.testing.assert_allclose(scene.mesh.normal[:, scene.mesh.shape == 3].T, [[1, 0, 0]] * 2, atol=1e-7)
    np.testing.assert_allclose(shape_triangles(scene, 3)[..., 0], 3.0, atol=1e-12)


def test_parameters_and_defaults(tmp_path):
    """$name takes the <default> value unless parameters= gives one; an undefined one names its line."""
    sensor = """<default name="spp" value="32"/><default name="r" value="0.25"/>
    <sensor type="perspective"><float name="fov" value="40"/>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="$h"/>
            <rfilter type="box"/></film></sensor>"""
    path = write(tmp_path, """<shape type="rectangle"><bsdf type="twosided">
        <bsdf type="diffuse"><rgb name="reflectance" value="$r"/></bsdf></bsdf></shape>""", sensor=sensor)
    with pytest.raises(SceneError, match=rf"line {line_of(path, '$h')}, <integer name=\"height\">: "
                                         r"undefined parameter \$h"):
        convert_mitsuba(path)
    data = convert_mitsuba(path, parameters={"h": 24, "r": "0.5"}).data
    assert data["camera"]["resolution"] == [16, 24] and data["render"] == {"spp": 32}
    assert data["materials"][f"diffuse@{line_of(path, 'diffuse')}"]["reflectance"] == [0.5, 0.5, 0.5]


@pytest.mark.parametrize("body, needle, message", [
    ('<shape type="cube"><bsdf type="plastic"/></shape>', "plastic", "bsdf type 'plastic' is not supported"),
    ('<shape type="cube"><bsdf type="roughconductor"/></shape>', "roughconductor", "distribution 'beckmann'"),
    ('<shape type="cube"><bsdf type="roughconductor"><string name="distribution" value="ggx"/>'
     '<float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.2"/></bsdf></shape>', "roughconductor",
     "anisotropic roughness"),
    ('<shape type="cube"><bsdf type="conductor"><string name="material" value="Au"/></bsdf></shape>', "conductor",
     "conductor preset 'Au'"),
    ('<shape type="cube"><bsdf type="conductor"><rgb name="eta" value="0.2"/><rgb name="k" value="3"/></bsdf></shape>',
     "conductor", "smooth conductor with Fresnel"),
    ('<shape type="cube"><bsdf type="diffuse"><texture type="bitmap" name="reflectance"/></bsdf></shape>', "bitmap",
     "textures are not supported"),
    ('<shape type="cube"><bsdf type="dielectric"><rgb name="specular_transmittance" value="0.5"/></bsdf></shape>',
     "specular_transmittance", "other than 1"),
    ('<shape type="cylinder"/>', "cylinder", "shape type 'cylinder' is not supported"),
    ('<shape type="cube"><medium type="homogeneous" name="interior"/></shape>', "medium", "<medium> is not supported"),
    ('<emitter type="envmap"/>', "envmap", "emitter type 'envmap' is not supported"),
    ('<emitter type="spot"><float name="cutoff_angle" value="30"/></emitter>', "spot", "falls off linearly"),
    ('<shape type="cube"><emitter type="area"><blackbody name="radiance" temperature="3000"/></emitter></shape>',
     "blackbody", "blackbody spectra"),
    ('<include filename="other.xml"/>', "include", "<include> is not supported"),
    ('<shape type="cube"><float name="bogus" value="1"/></shape>', "bogus", "parameter 'bogus'"),
])
def test_unsupported_features_are_errors_naming_element_and_line(tmp_path, body, needle, message):
    path = write(tmp_path, body)
    with pytest.raises(SceneError) as error:
        convert_mitsuba(path)
    text = str(error.value)
    assert text.startswith(f"{path}: 1 Mitsuba feature(s) pathspace cannot render")
    assert f"line {line_of(path, needle)}, <" in text and message in text, text


def test_every_unsupported_feature_is_listed_in_one_error(tmp_path):
    sensor = SENSOR.replace('<rfilter type="box"/>', '<rfilter type="box"/><integer name="crop_width" value="8"/>')
    path = write(tmp_path, '<shape type="cube"><bsdf type="plastic"/></shape>\n<texture type="checkerboard" id="t"/>\n'
                           '<emitter type="sunsky"/>', sensor=sensor)
    with pytest.raises(SceneError, match=r"4 Mitsuba feature\(s\)") as error:
        convert_mitsuba(path)
    lines = str(error.value).splitlines()[1:]
    assert [int(line.split(",")[0][7:]) for line in lines] == [line_of(path, needle) for needle in
                                                                ("<film", "plastic", "checkerboard", "sunsky")]


@pytest.mark.parametrize("text, message", [
    ('<scene version="3.0.0"><shape type="cube"></scene>', r"line 1: not well-formed XML: mismatched tag"),
    ('<scene version="3.0.0">\n<shape type="cube"/>\n', r"line 3: not well-formed XML: no element found"),
    ('<scene><shape type="cube"/></scene>', r"line 1, <scene>: missing version attribute"),
    ('<?xml version="1.0" encoding="utf-9"?>\n<scene version="3.0.0"/>', r"line 1: unknown encoding: utf-9"),
    ('<scene version="3.0.0">' + "<bsdf>\n" * 64, r"line 64, <bsdf>: elements nested deeper than 64"),
    ('<scene version="3.0.0">\n<shape type="cube"><ref id="nothing"/></shape></scene>',
     r"line 2, <ref id=\"nothing\">: unknown reference id 'nothing'"),
    ('<scene version="3.0.0">\n<bsdf type="diffuse" id="a"/>\n<bsdf type="diffuse" id="a"/></scene>',
     r"line 3, <bsdf type=\"diffuse\" id=\"a\">: duplicate id 'a' \(first at line 2\)"),
    ('<scene version="3.0.0">\n<shape type="sphere"><float name="radius" value="big"/></shape></scene>',
     r"line 2, <float name=\"radius\">: expected a number, got 'big'"),
    ('<scene version="3.0.0">\n<shape type="cube"><transform name="to_world"><rotate angle="3"/></transform></shape>'
     '</scene>', r"line 2, <rotate>: rotation axis cannot be zero"),
    ('<scene version="3.0.0">\n<shape type="cube"><bsdf type="diffuse"><rgb name="reflectance" value="1, 2"/></bsdf>'
     '</shape></scene>', r"line 2, <rgb name=\"reflectance\">: expected 1 or 3 numbers, got '1, 2'"),
    ('<scene version="3.0.0">\n<shape type="cube"><bsdf type="dielectric"><string name="int_ior" value="glas"/>'
     '</bsdf></shape></scene>', r"line 2, <string name=\"int_ior\">: unknown index of refraction 'glas' \(known: "
                                 r"vacuum"),
])
def test_malformed_files_are_clear_errors(tmp_path, text, message):
    path = tmp_path / "bad.xml"
    path.write_text(text)
    with pytest.raises(SceneError, match=rf"^{path}: {message}"):
        ps.load_scene(path)


def test_errors_of_the_description_name_the_element(tmp_path):
    """Values pathspace refuses (a reflectance above 1) are reported by the TOML checks, with the element."""
    path = write(tmp_path, FLOOR.replace("<bsdf type=\"diffuse\"/>",
                                         '<bsdf type="diffuse"><rgb name="reflectance" value="1.5"/></bsdf>'))
    with pytest.raises(SceneError, match=rf"line {line_of(path, 'twosided')}, <bsdf type=\"twosided\">: "
                                         r"materials.diffuse@\d+.reflectance: expected 3 finite numbers in \[0, 1\]"):
        load_xml(path)


def test_fields_of_view_and_indices_of_refraction(tmp_path):
    """fov_axis diagonal and a focal length (35 mm film) become horizontal fields of view (Mitsuba's
    parse_fov); named indices come from Mitsuba's table, ext_ior defaults to air."""
    diagonal = write(tmp_path, FLOOR, sensor=SENSOR.replace('value="40"/>', 'value="40"/><string name="fov_axis" '
                                                                             'value="diagonal"/>'), name="d.xml")
    camera = convert_mitsuba(diagonal).data["camera"]
    assert camera["fov_axis"] == "x"
    assert camera["fov"] == pytest.approx(math.degrees(2 * math.atan(math.tan(math.radians(20)) * 16 / 20)))
    focal = write(tmp_path, FLOOR, sensor=SENSOR.replace('<float name="fov" value="40"/>', ""), name="f.xml")
    assert convert_mitsuba(focal).data["camera"]["fov"] == pytest.approx(
        math.degrees(2 * math.atan(math.hypot(36, 24) / 100 * 16 / 20)))  # 50 mm by default
    assert convert_mitsuba(focal, resolution=(20, 20)).data["camera"]["fov"] == pytest.approx(
        math.degrees(2 * math.atan(math.hypot(36, 24) / 100 / math.sqrt(2))))
    glass = write(tmp_path, '<shape type="cube"><bsdf type="dielectric"/></shape>', name="g.xml")
    assert convert_mitsuba(glass).data["materials"][f"dielectric@{line_of(glass, 'dielectric')}"]["ior"] == (
        NAMED_IORS["bk7"] / NAMED_IORS["air"])


def test_lights(tmp_path):
    """Point, spot (a hard edge), directional and constant emitters, with Mitsuba's local frames (+z forward)."""
    path = write(tmp_path, FLOOR + """
    <emitter type="point"><point name="position" value="1, 2, 3"/><rgb name="intensity" value="4, 5, 6"/></emitter>
    <emitter type="spot">
        <transform name="to_world"><rotate value="1, 0, 0" angle="90"/><translate value="0, 2, 0"/></transform>
        <float name="cutoff_angle" value="30"/><float name="beam_width" value="30"/></emitter>
    <emitter type="directional"><transform name="to_world"><rotate value="0, 1, 0" angle="90"/></transform>
        <rgb name="irradiance" value="2"/></emitter>
    <emitter type="constant"><spectrum name="radiance" value="0.5"/></emitter>""")
    scene, _ = load_xml(path)
    point, spot, directional, environment = world_lights(scene)
    assert (point.position, point.intensity) == ((1.0, 2.0, 3.0), (4.0, 5.0, 6.0))
    np.testing.assert_allclose(spot.position, [0, 2, 0])
    np.testing.assert_allclose(spot.axis, [0, -1, 0], atol=1e-12)  # +z turned 90 degrees about x points down
    assert (spot.cone_angle, spot.falloff_start, spot.intensity) == (30.0, 30.0, (1.0, 1.0, 1.0))
    np.testing.assert_allclose(directional.unit_direction, [1, 0, 0], atol=1e-12)
    assert directional.irradiance == (2.0, 2.0, 2.0) and environment.radiance == (0.5, 0.5, 0.5)


def test_spheres_and_disks_are_tessellated_with_a_warning(tmp_path):
    path = write(tmp_path, """
    <shape type="sphere"><point name="center" value="0, 1, 0"/><float name="radius" value="0.5"/>
        <transform name="to_world"><scale value="2"/><translate value="10, 0, 0"/></transform></shape>
    <shape type="disk"><transform name="to_world"><scale value="3"/></transform></shape>""")
    scene, messages = load_xml(path)
    sphere, disk = scene.mesh.shape == 0, scene.mesh.shape == 1
    assert sphere.sum() == 20 * 4 ** 5 and disk.sum() == 256
    centre = scene.to_world(scene.mesh.vertices[scene.mesh.indices[sphere]]).reshape(-1, 3) - [10, 2, 0]
    np.testing.assert_allclose(np.linalg.norm(centre, axis=1), 1.0, rtol=1e-12)  # radius 0.5, scaled by 2
    np.testing.assert_allclose(scene.mesh.area[sphere].sum() / (4 * np.pi), 1 - 2.99e-4, atol=1e-6)
    kept = 256 * math.sin(2 * math.pi / 256) / (2 * math.pi)
    np.testing.assert_allclose(scene.mesh.area[disk].sum(), 9 * np.pi * kept, rtol=1e-12)
    np.testing.assert_allclose(scene.mesh.normal[:, disk].T, [[0, 0, 1]] * 256, atol=1e-7)
    assert any(f"line {line_of(path, 'sphere')}, " in m and "20480 triangles: 0.030% less area" in m for m in messages)
    assert any(f"line {line_of(path, 'disk')}, " in m and "256 triangles: 0.010% less area" in m for m in messages)


def test_mirroring_transforms_keep_mitsubas_normals(tmp_path):
    """Under scale z = -1, Mitsuba's meshes and spheres keep their winding (a mesh facing +z then faces +z,
    a sphere's normals point inwards), its rectangles turn their normal (to -z), as measured with Mitsuba 3.9."""
    trimesh.Trimesh([[-1, -1, 0], [1, -1, 0], [0, 1, 0]], [[0, 1, 2]]).export(tmp_path / "tri.ply")
    mirror = '<transform name="to_world"><scale value="1, 1, -1"/></transform>'
    path = write(tmp_path, f"""<shape type="ply"><string name="filename" value="tri.ply"/>
        <boolean name="face_normals" value="true"/>{mirror}</shape>
    <shape type="rectangle">{mirror}</shape>
    <shape type="sphere">{mirror}</shape>""")
    scene, _ = load_xml(path)
    normals = [scene.mesh.normal[:, scene.mesh.shape == i].T for i in range(3)]
    np.testing.assert_allclose(normals[0], [[0, 0, 1]], atol=1e-7)
    np.testing.assert_allclose(normals[1], [[0, 0, -1]] * 2, atol=1e-7)
    centroids = scene.to_world(scene.mesh.vertices[scene.mesh.indices[scene.mesh.shape == 2]]).mean(axis=1)
    assert np.all(np.sum(centroids * normals[2], axis=1) < 0)


def test_smooth_shading_and_clipping_are_reported(tmp_path):
    """A mesh Mitsuba would shade with interpolated normals, and geometry beyond far_clip, give warnings."""
    trimesh.creation.icosphere(subdivisions=1).export(tmp_path / "ball.obj")
    trimesh.creation.box().export(tmp_path / "box.obj")
    path = write(tmp_path, """<shape type="obj"><string name="filename" value="ball.obj"/></shape>
    <shape type="obj"><string name="filename" value="ball.obj"/><boolean name="face_normals" value="true"/></shape>
    <shape type="obj"><string name="filename" value="box.obj"/><boolean name="face_normals" value="true"/></shape>""",
                 sensor=SENSOR.replace('<float name="fov"', '<float name="far_clip" value="5"/><float name="fov"'))
    _, messages = load_xml(path)
    smooth = [m for m in messages if "interpolates" in m]
    assert len(smooth) == 1 and smooth[0].startswith(f"  line {line_of(path, 'ball.obj')}, <shape")
    [clip] = [m for m in messages if "far_clip" in m]
    assert "far_clip = 5 but geometry reaches 6 along the view axis" in clip


def test_toml_transform_matrix_and_disk():
    """The TOML features Mitsuba scenes need: a 4 x 4 affine matrix (checked) and disks."""
    matrix = [[0, -1, 0, 1], [2, 0, 0, 0], [0, 0, 1, 3], [0, 0, 0, 1]]
    scene = load(scene_with(shapes__0__transform={"matrix": matrix}))
    corners = np.unique(scene.mesh.vertices[scene.mesh.indices[scene.mesh.shape == 0]].reshape(-1, 3), axis=0)
    np.testing.assert_allclose(scene.to_world(corners), [[0, -2, 3], [0, 2, 3], [2, -2, 3], [2, 2, 3]], atol=1e-12)
    for transform, message in [({"matrix": matrix, "scale": 2}, "a matrix replaces scale, rotate and translate"),
                               ({"matrix": matrix[:3]}, r"expected 4 rows of 4 numbers, the last \[0, 0, 0, 1\]"),
                               ({"matrix": [[0] * 4] * 3 + [[0, 0, 0, 1]]}, "expected an invertible matrix")]:
        with pytest.raises(SceneError, match=rf"shapes\[0\] \('floor'\).transform.matrix: {message}"):
            load(scene_with(shapes__0__transform=transform))
    disk = load(scene_with(shapes__0={"type": "disk", "center": [0, 0, 1], "normal": [0, 2, 0], "radius": 2,
                                      "segments": 6, "material": "grey"}))
    triangles = disk.mesh.shape == 0
    np.testing.assert_allclose(disk.mesh.area[triangles].sum(), 6 * 0.5 * 4 * math.sin(math.pi / 3))
    np.testing.assert_allclose(disk.mesh.normal[:, triangles].T, [[0, 1, 0]] * 6, atol=1e-7)
    with pytest.raises(SceneError, match=r"shapes\[0\].segments: expected an integer >= 3"):
        load(scene_with(shapes__0={"type": "disk", "radius": 1, "segments": 2, "material": "grey"}))
