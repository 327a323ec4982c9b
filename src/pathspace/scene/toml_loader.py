"""The TOML scene format (one front end of the scene model).

The format is documented in ``docs/scene-format.md``.  Every error names the
file, the field and what was expected; see :mod:`pathspace.scene.fields`.
"""
from __future__ import annotations

import os
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from ..bsdfs import KINDS, MaterialTable
from ..camera import FOV_AXES, PinholeCamera, ThinLensCamera
from ..lights import AreaLights, DirectionalLight, Environment, LightSet, PointLight, SpotLight
from ..spectra import Blackbody, Cauchy, Colour, ColourTable, Illuminant, SampledSpectrum, Sellmeier, check_emission
from . import shapes as builtin
from .errors import SceneError
from .fields import Fields
from .mesh import TriangleMesh, triangle_cross
from .model import Scene

__all__ = ["load_scene", "scene_from_dict", "FORMAT_VERSION"]

FORMAT_VERSION = 1
SHAPE_TYPES = ("triangles", "mesh", "quad", "box", "sphere")
MATERIAL_TYPES = ("diffuse", "phong", "mirror", "dielectric", "conductor")
CAMERA_TYPES = ("pinhole", "thinlens")
LIGHT_TYPES = ("point", "spot", "directional", "environment")
# A triangle is degenerate when |(p1-p0) x (p2-p0)| <= DEGENERATE_RELATIVE * (longest edge)^2,
# i.e. its vertices are collinear to within float rounding.
DEGENERATE_RELATIVE = 1e-10
# An icosphere of 8 subdivisions has 1.3 million triangles; beyond that memory runs out quickly.
MAX_SUBDIVISIONS = 8
# Geometry is traced in float32: coordinates must stay well inside its range.
MAX_COORDINATE = 1e30


def load_scene(path: str | os.PathLike) -> Scene:
    """Load a scene from a TOML file; mesh files are found relative to its folder."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"{path}: scene file not found")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as error:
        raise SceneError(f"{path}: not a valid TOML file: {error}") from None
    except UnicodeDecodeError as error:
        raise SceneError(f"{path}: not a UTF-8 text file: {error}") from None
    return scene_from_dict(data, source=str(path), base_dir=path.parent)


def scene_from_dict(data: dict[str, Any], source: str = "<scene dict>",
                    base_dir: str | os.PathLike | None = None) -> Scene:
    """Build a scene from the parsed contents of a scene file (a dict of the TOML structure)."""
    top = Fields(data, "", source)
    version = top.integer("format", FORMAT_VERSION, low=1)
    if version != FORMAT_VERSION:
        raise top.error(f"this pathspace reads scene format {FORMAT_VERSION}, got {version}", "format")
    top.string("name", "")
    top.string("description", "")
    base = Path(base_dir) if base_dir is not None else Path.cwd()
    camera = _camera(top.sub("camera"))
    material_names, materials = _materials(top.sub("materials"), base)
    shape_list = top.raw("shapes", None)
    if not isinstance(shape_list, list) or not shape_list:
        raise top.error("expected a non-empty array of tables ([[shapes]])", "shapes")
    light_list = top.raw("lights", [])
    if not isinstance(light_list, list):
        raise top.error("expected an array of tables ([[lights]])", "lights")
    other_lights = [_light(Fields(table, f"lights[{i}]", source), base) for i, table in enumerate(light_list)]
    environments = [i for i, light in enumerate(other_lights) if isinstance(light, Environment)]
    if len(environments) > 1:
        raise top.error(f"at most one environment light is supported, got {len(environments)} "
                        f"(lights{environments})", "lights")
    top.finish()

    vertices, indices, material_ids, shape_ids, names = [], [], [], [], []
    emit_tris, emit_light, emit_radiance, emit_two_sided = [], [], [], []
    offset = triangle_offset = 0
    for i, table in enumerate(shape_list):
        shape = Fields(table, f"shapes[{i}]", source)
        name = shape.string("name", f"shapes[{i}]")
        if name != f"shapes[{i}]":
            shape.path = f"shapes[{i}] ({name!r})"
        v, f = _shape_geometry(shape, base)
        material = shape.string("material")
        if material not in material_names:
            raise shape.error(f"unknown material {material!r} (defined: {', '.join(material_names)})", "material")
        emitter = shape.sub("emitter", None)
        radiance = two_sided = None
        if emitter is not None:
            radiance = _built(emitter, lambda: check_emission(_colour(emitter, "radiance", base=base), "radiance"))
            two_sided = emitter.boolean("two_sided", False)
            emitter.finish()
        shape.finish()

        vertices.append(v)
        indices.append(f + offset)
        material_ids.append(np.full(len(f), material_names.index(material)))
        shape_ids.append(np.full(len(f), i))
        names.append(name)
        if radiance is not None:
            emit_tris.append(triangle_offset + np.arange(len(f)))
            emit_light.append(np.full(len(f), len(emit_radiance)))
            emit_radiance.append(radiance)
            emit_two_sided.append(two_sided)
        offset += len(v)
        triangle_offset += len(f)

    mesh = TriangleMesh(np.concatenate(vertices), np.concatenate(indices), np.concatenate(material_ids),
                        np.concatenate(shape_ids))
    area = AreaLights(mesh, np.concatenate(emit_tris or [np.zeros(0, np.int64)]),
                      np.concatenate(emit_light or [np.zeros(0, np.int64)]), ColourTable(emit_radiance, "illuminant"),
                      np.array(emit_two_sided, dtype=bool))
    # Infinite lights: their power (for light selection) is what crosses the geometry's bounding sphere;
    # light tracing and BDPT start their rays on a disk outside a sphere that also holds a thin lens.
    lo, hi = mesh.bounds()
    scene_radius = 0.5 * float(np.linalg.norm(hi - lo))
    if camera.lens_radius > 0:
        lo = np.minimum(lo, camera.position - camera.lens_radius)
        hi = np.maximum(hi, camera.position + camera.lens_radius)
    lights = LightSet(area, other_lights, scene_radius=scene_radius, disk_center=0.5 * (lo + hi),
                      disk_radius=0.5 * float(np.linalg.norm(hi - lo)))
    return Scene(camera=camera, mesh=mesh, materials=MaterialTable(material_names, materials), lights=lights,
                 shape_names=names, source=source)


def _camera(fields: Fields) -> PinholeCamera:
    kind = fields.string("type", "pinhole", choices=CAMERA_TYPES)
    position = fields.vector("position", 3)
    look_at = fields.vector("look_at", 3)
    up = fields.vector("up", 3, [0.0, 1.0, 0.0])
    fov = fields.number("fov", low=0.0, high=180.0, low_open=True, high_open=True)
    fov_axis = fields.string("fov_axis", "smaller", choices=FOV_AXES)
    width, height = fields.vector("resolution", 2, integer=True, low=1)
    lens = {}
    if kind == "thinlens":
        lens["aperture_radius"] = fields.number("aperture_radius", low=0.0, low_open=True)
        if fields.has("focus_distance"):
            lens["focus_distance"] = fields.number("focus_distance", low=0.0, low_open=True)
    fields.finish()
    if kind == "thinlens":
        return _built(fields, lambda: ThinLensCamera(position, look_at, up, fov, int(width), int(height),
                                                     fov_axis=fov_axis, **lens))
    return _built(fields, lambda: PinholeCamera(position, look_at, up, fov, int(width), int(height), fov_axis=fov_axis))


def _colour(fields: Fields, name: str, default=Fields.REQUIRED, *, base: Path) -> Colour:
    """An RGB triple of numbers >= 0, or a spectrum table (see docs/scene-format.md)."""
    value = fields.raw(name, default)
    if isinstance(value, dict):
        return _spectrum(fields.sub(name), base)
    if not isinstance(value, (list, tuple)):
        raise fields.error(f"expected 3 numbers (RGB) or a spectrum table, got {value!r}", name)
    return tuple(float(x) for x in fields.vector(name, 3, default, low=0.0))


def _spectrum(fields: Fields, base: Path) -> Colour:
    forms = [key for key in ("wavelengths", "file", "blackbody", "illuminant") if fields.has(key)]
    if len(forms) != 1:
        raise fields.error("expected exactly one of: wavelengths (with values), file, blackbody, illuminant", None)
    scale = fields.number("scale", 1.0, low=0.0)
    form = forms[0]
    if form == "wavelengths":
        wavelengths = fields.raw("wavelengths")
        values = fields.raw("values")
        if not (isinstance(wavelengths, list) and isinstance(values, list)):
            raise fields.error("expected lists of wavelengths (nm) and values of the same length", "wavelengths")
        spectrum = _built(fields, lambda: SampledSpectrum(tuple(wavelengths), tuple(values), scale))
    elif form == "file":
        path = base / fields.string("file")
        if not path.is_file():
            raise fields.error(f"spectrum file not found: {path}", "file")
        spectrum = _built(fields, lambda: SampledSpectrum.from_csv(path, scale))
    elif form == "blackbody":
        spectrum = _built(fields, lambda: Blackbody(fields.number("blackbody", low=0.0, low_open=True), scale))
    else:
        spectrum = _built(fields, lambda: Illuminant(fields.string("illuminant"), scale))
        _built(fields, spectrum.on_grid)  # an unknown name fails here, with the names colour-science knows
    fields.finish()
    return spectrum


def _ior(fields: Fields):
    """A number > 0, or a dispersion law: { cauchy = [a, b] } or { sellmeier = { b = [...], c = [...] } }."""
    value = fields.raw("ior", 1.5)
    if not isinstance(value, dict):
        return fields.number("ior", 1.5, low=0.0, low_open=True)
    law = fields.sub("ior")
    if not (law.has("cauchy") or law.has("sellmeier")):
        raise fields.error("expected a number > 0 or a dispersion law: { cauchy = [a, b] } or "
                           "{ sellmeier = { b = [...], c = [...] } }", "ior")
    if law.has("cauchy"):
        a, b = law.vector("cauchy", 2)
        result = _built(law, lambda: Cauchy(float(a), float(b)))
    else:
        sellmeier = law.sub("sellmeier")
        b, c = sellmeier.vector("b", 3), sellmeier.vector("c", 3)
        sellmeier.finish()
        result = _built(law, lambda: Sellmeier(tuple(b), tuple(c)))
    law.finish()
    return result


def _built(fields: Fields, make):
    """``make()``, with a ValueError of the form "field: message" turned into a SceneError naming the field."""
    try:
        return make()
    except ValueError as error:
        field, _, message = str(error).partition(": ")
        raise fields.error(message or str(error), field if message else None) from None


def _material(table: Fields, base: Path):
    kind = table.string("type", choices=MATERIAL_TYPES)
    if kind == "diffuse":
        args = (_colour(table, "reflectance", base=base),)
    elif kind == "mirror":
        args = (_colour(table, "reflectance", [1.0, 1.0, 1.0], base=base),)
    elif kind == "dielectric":
        args = (_ior(table),)
    elif kind == "conductor":
        args = (_colour(table, "eta", base=base), _colour(table, "k", base=base), table.number("alpha"))
    else:
        args = (_colour(table, "diffuse", base=base), _colour(table, "specular", base=base),
                table.number("exponent", low=0.0))
    table.finish()
    return _built(table, lambda: KINDS[kind](*args))


def _materials(fields: Fields, base: Path) -> tuple[list[str], list]:
    names, materials = [], []
    for name in fields.table:
        materials.append(_material(fields.sub(name), base))
        names.append(name)
    if not names:
        raise fields.error("expected at least one material", None)
    return names, materials


def _light(fields: Fields, base: Path):
    kind = fields.string("type", choices=LIGHT_TYPES)
    if kind == "point":
        args = (tuple(fields.vector("position", 3)), _colour(fields, "intensity", base=base))
    elif kind == "spot":
        cone = fields.number("cone_angle", 30.0, low=0.0, high=90.0, low_open=True)
        args = (tuple(fields.vector("position", 3)), tuple(fields.vector("look_at", 3)),
                _colour(fields, "intensity", base=base), cone,
                fields.number("falloff_start", min(25.0, cone), low=0.0, high=cone))
    elif kind == "directional":
        args = (tuple(fields.vector("direction", 3)), _colour(fields, "irradiance", base=base))
    else:
        args = (_colour(fields, "radiance", base=base),)
    fields.finish()
    light_types = {"point": PointLight, "spot": SpotLight, "directional": DirectionalLight,
                   "environment": Environment}
    return _built(fields, lambda: light_types[kind](*args))


def _shape_geometry(shape: Fields, base: Path) -> tuple[np.ndarray, np.ndarray]:
    kind = shape.string("type", choices=SHAPE_TYPES)
    if kind == "triangles":
        v = shape.array("vertices", 3)
        f = shape.array("triangles", 3, integer=True)
        if f.min() < 0 or f.max() >= len(v):
            raise shape.error(f"vertex indices must lie in [0, {len(v) - 1}], got {f.min()}..{f.max()}", "triangles")
    elif kind == "mesh":
        v, f = _mesh_file(shape, base)
    elif kind == "quad":
        v, f = builtin.quad(shape.vector("corner", 3), shape.vector("edge_u", 3), shape.vector("edge_v", 3))
    elif kind == "box":
        size = shape.vector("size", 3, low=0.0)
        if np.any(size <= 0):
            raise shape.error(f"expected 3 numbers > 0, got {size.tolist()}", "size")
        v, f = builtin.box(shape.vector("center", 3, [0.0, 0.0, 0.0]), size)
    else:
        v, f = builtin.sphere(shape.vector("center", 3, [0.0, 0.0, 0.0]),
                              shape.number("radius", low=0.0, low_open=True),
                              shape.integer("subdivisions", 3, low=0, high=MAX_SUBDIVISIONS))
    transform = shape.sub("transform", None)
    mirrored = False
    if transform is not None:
        v, mirrored = _apply_transform(transform, v)
    # A mirroring transform reverses the winding; undo that so normals keep facing the same way.
    if shape.boolean("flip_normals", False) != mirrored:
        f = f[:, ::-1]
    return v, _check_triangles(shape, v, f, shape.boolean("drop_degenerate", False))


def _mesh_file(shape: Fields, base: Path) -> tuple[np.ndarray, np.ndarray]:
    name = shape.string("file")
    path = (base / name) if not os.path.isabs(name) else Path(name)
    if not path.is_file():
        raise shape.error(f"mesh file not found: {path}", "file")
    try:
        mesh = trimesh.load(str(path), force="mesh", process=False)
    except Exception as error:  # trimesh raises many types for unreadable files
        raise shape.error(f"cannot read mesh file {path}: {error}", "file") from None
    v = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=np.float64)
    f = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64)
    if f.size == 0:
        raise shape.error(f"mesh file {path} contains no triangles", "file")
    if not np.all(np.isfinite(v)):
        raise shape.error(f"mesh file {path} has non-finite vertex coordinates", "file")
    if f.ndim != 2 or f.shape[1] != 3 or f.min() < 0 or f.max() >= len(v):
        raise shape.error(f"mesh file {path} has faces referring to vertices outside 0..{len(v) - 1}", "file")
    return v, f


def _apply_transform(fields: Fields, v: np.ndarray) -> np.ndarray:
    scale = fields.raw("scale", 1.0)
    if isinstance(scale, list):
        scale = fields.vector("scale", 3)
    else:
        scale = np.full(3, fields.number("scale", 1.0))
    if np.any(scale == 0):
        raise fields.error(f"expected non-zero scale factors, got {scale.tolist()}", "scale")
    axis, angle = np.array([0.0, 1.0, 0.0]), 0.0
    rotate = fields.sub("rotate", None)
    if rotate is not None:
        axis = rotate.vector("axis", 3)
        angle = rotate.number("angle")
        if not np.any(axis != 0):
            raise rotate.error("expected a non-zero rotation axis", "axis")
        rotate.finish()
    translate = fields.vector("translate", 3, [0.0, 0.0, 0.0])
    fields.finish()
    matrix = builtin.transform_matrix(scale, axis, angle, translate)
    return v @ matrix[:3, :3].T + matrix[:3, 3], bool(np.linalg.det(matrix[:3, :3]) < 0)


def _check_triangles(shape: Fields, v: np.ndarray, f: np.ndarray, drop_degenerate: bool) -> np.ndarray:
    if not np.all(np.isfinite(v)) or np.abs(v).max() > MAX_COORDINATE:
        raise shape.error(f"vertex coordinates must be finite and within +-{MAX_COORDINATE:g} (float32 geometry)",
                          None)
    cross = np.linalg.norm(triangle_cross(v, f), axis=1)
    p = v[f]
    longest2 = np.max([np.sum((p[:, a] - p[:, b]) ** 2, axis=1) for a, b in ((0, 1), (1, 2), (2, 0))], axis=0)
    degenerate = ~(cross > DEGENERATE_RELATIVE * longest2)
    if np.any(degenerate):
        if not drop_degenerate:
            first = int(np.flatnonzero(degenerate)[0])
            raise shape.error(
                f"{int(degenerate.sum())} degenerate (zero-area) triangle(s), the first is triangle {first} with "
                f"vertices {v[f[first]].tolist()}; fix the geometry or set drop_degenerate = true", None)
        f = f[~degenerate]
        if len(f) == 0:
            raise shape.error("every triangle is degenerate (zero area)", None)
    return f
