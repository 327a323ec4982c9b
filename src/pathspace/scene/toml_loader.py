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

from ..camera import PinholeCamera
from ..lights import AreaLights
from ..materials import Diffuse, MaterialTable
from . import shapes as builtin
from .errors import SceneError
from .fields import Fields
from .mesh import TriangleMesh, triangle_cross
from .model import Scene

__all__ = ["load_scene", "scene_from_dict", "FORMAT_VERSION"]

FORMAT_VERSION = 1
SHAPE_TYPES = ("triangles", "mesh", "quad", "box", "sphere")
MATERIAL_TYPES = ("diffuse",)
CAMERA_TYPES = ("pinhole",)
# A triangle is degenerate when |(p1-p0) x (p2-p0)| <= DEGENERATE_RELATIVE * (longest edge)^2,
# i.e. its vertices are collinear to within float rounding.
DEGENERATE_RELATIVE = 1e-10


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
    camera = _camera(top.sub("camera"))
    material_names, materials = _materials(top.sub("materials"))
    shape_list = top.raw("shapes", None)
    if not isinstance(shape_list, list) or not shape_list:
        raise top.error("expected a non-empty array of tables ([[shapes]])", "shapes")
    top.finish()

    base = Path(base_dir) if base_dir is not None else Path.cwd()
    vertices, indices, material_ids, shape_ids, names = [], [], [], [], []
    emit_tris, emit_radiance, emit_two_sided, emit_light = [], [], [], []
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
            radiance = emitter.vector("radiance", 3, low=0.0)
            if not np.any(radiance > 0):
                raise emitter.error("expected at least one positive component (remove the emitter instead)",
                                    "radiance")
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
            emit_radiance.append(np.repeat(radiance[:, None], len(f), axis=1))
            emit_two_sided.append(np.full(len(f), two_sided))
            emit_light.append(np.full(len(f), len(emit_tris) - 1))
        offset += len(v)
        triangle_offset += len(f)

    mesh = TriangleMesh(np.concatenate(vertices), np.concatenate(indices), np.concatenate(material_ids),
                        np.concatenate(shape_ids))
    if emit_tris:
        lights = AreaLights(mesh, np.concatenate(emit_tris), np.concatenate(emit_radiance, axis=1),
                            np.concatenate(emit_two_sided), np.concatenate(emit_light))
    else:
        lights = AreaLights(mesh, np.zeros(0, np.int64), np.zeros((3, 0)), np.zeros(0, bool), np.zeros(0, np.int64))
    return Scene(camera=camera, mesh=mesh, materials=MaterialTable(material_names, materials), lights=lights,
                 shape_names=names, source=source)


def _camera(fields: Fields) -> PinholeCamera:
    fields.string("type", "pinhole", choices=CAMERA_TYPES)
    position = fields.vector("position", 3)
    look_at = fields.vector("look_at", 3)
    up = fields.vector("up", 3, [0.0, 1.0, 0.0])
    fov = fields.number("fov", low=0.0, high=180.0, low_open=True, high_open=True)
    fov_axis = fields.string("fov_axis", "smaller", choices=("x", "y", "smaller", "larger"))
    width, height = fields.vector("resolution", 2, integer=True, low=1)
    fields.finish()
    try:
        return PinholeCamera(position, look_at, up, fov, int(width), int(height), fov_axis=fov_axis)
    except ValueError as error:
        field, _, message = str(error).partition(": ")
        raise fields.error(message or str(error), field if message else None) from None


def _materials(fields: Fields) -> tuple[list[str], list[Diffuse]]:
    names, materials = [], []
    for name in fields.table:
        table = fields.sub(name)
        kind = table.string("type", choices=MATERIAL_TYPES)
        if kind == "diffuse":
            reflectance = table.vector("reflectance", 3, low=0.0)
            if np.any(reflectance > 1.0):
                raise table.error(f"expected 3 numbers in [0, 1] (an albedo above 1 creates energy), "
                                  f"got {reflectance.tolist()}", "reflectance")
            materials.append(Diffuse(tuple(float(x) for x in reflectance)))
        table.finish()
        names.append(name)
    if not names:
        raise fields.error("expected at least one material", None)
    return names, materials


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
                              shape.integer("subdivisions", 3, low=0))
    transform = shape.sub("transform", None)
    if transform is not None:
        v = _apply_transform(transform, v)
    if shape.boolean("flip_normals", False):
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
    return v @ matrix[:3, :3].T + matrix[:3, 3]


def _check_triangles(shape: Fields, v: np.ndarray, f: np.ndarray, drop_degenerate: bool) -> np.ndarray:
    if not np.all(np.isfinite(v)):
        raise shape.error("vertex coordinates must be finite", None)
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
