"""The TOML scene format (one front end of the scene model).

The format is documented in ``docs/scene-format.md``.  The loader reads the
structure -- camera, materials, shapes (with their emitters and transforms),
lights -- and hands each table to the model its ``type`` names (the
registries :data:`pathspace.camera.CAMERAS`, :data:`pathspace.bsdfs.KINDS`,
:data:`pathspace.scene.shapes.SHAPES`, :data:`pathspace.lights.LIGHTS`),
which reads and validates its own fields.  Every error names the file, the
field and what was expected; see :mod:`pathspace.fields`.
"""
from __future__ import annotations

import hashlib
import json
import os
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from ..bsdfs import KINDS, MaterialTable
from ..camera import CAMERAS
from ..fields import MAX_COORDINATE, Fields, SceneError
from ..lights import LIGHTS, AreaLight, LightSet
from . import shapes as builtin
from .mesh import TriangleMesh, triangle_cross
from .model import TRAVERSALS, Scene
from .overrides import apply_overrides
from .shapes import SHAPES

__all__ = ["load_scene", "scene_from_dict", "FORMAT_VERSION"]

FORMAT_VERSION = 1
# The range of geometry float32 traces faithfully, relative to the render origin (see _check_extent).
MAX_RENDER_COORDINATE = 1e12
MIN_SCENE_EXTENT = 1e-8
# A triangle is degenerate when |(p1-p0) x (p2-p0)| <= DEGENERATE_RELATIVE * (longest edge)^2,
# i.e. its vertices are collinear to within float rounding.
DEGENERATE_RELATIVE = 1e-10


def load_scene(path: str | os.PathLike, *, resolution: tuple[int, int] | None = None, spp: int | None = None,
               **overrides: Any) -> Scene:
    """Load a scene from a TOML file, or from a Mitsuba XML file (``.xml``, read by
    :func:`pathspace.scene.mitsuba_xml.load_mitsuba`); mesh and spectrum files are found relative to its folder.

    ``resolution``, ``spp`` and any ``overrides`` ({"materials.white.reflectance": [0.5, 0.5, 0.5], ...})
    change the description before it is checked (see :mod:`pathspace.scene.overrides`).
    """
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"{path}: scene file not found")
    if path.suffix.lower() == ".xml":
        from .mitsuba_xml import load_mitsuba  # it builds on this module

        return load_mitsuba(path, resolution=resolution, spp=spp, **overrides)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as error:
        raise SceneError(f"{path}: not a valid TOML file: {error}") from None
    except UnicodeDecodeError as error:
        raise SceneError(f"{path}: not a UTF-8 text file: {error}") from None
    except RecursionError:  # tomllib parses nested arrays and tables recursively
        raise SceneError(f"{path}: not a valid TOML file: arrays or tables nested too deeply") from None
    return scene_from_dict(data, source=str(path), base_dir=path.parent, resolution=resolution, spp=spp, **overrides)


def _model(fields: Fields, registry: dict, default: str | None = None):
    """The model the table's ``type`` names, read from the table by the model itself."""
    kind = fields.string("type", default if default is not None else Fields.REQUIRED, choices=registry)
    return registry[kind].from_fields(fields)


def scene_from_dict(data: dict[str, Any], source: str = "<scene dict>", base_dir: str | os.PathLike | None = None,
                    *, resolution: tuple[int, int] | None = None, spp: int | None = None, **overrides: Any) -> Scene:
    """Build a scene from the parsed contents of a scene file (a dict of the TOML structure), after
    applying ``resolution``, ``spp`` and ``overrides`` as :func:`load_scene` does."""
    data = apply_overrides(data, {"resolution": resolution, "spp": spp, **overrides}, source)
    top = Fields(data, "", source, base_dir)
    version = top.integer("format", FORMAT_VERSION, low=1)
    if version != FORMAT_VERSION:
        raise top.error(f"this pathspace reads scene format {FORMAT_VERSION}, got {version}", "format")
    top.string("name", "")
    top.string("description", "")
    render = top.sub("render", {})
    render_spp = render.integer("spp", None, low=1) if render.has("spp") else None
    traversal = render.string("traversal", "watertight", choices=TRAVERSALS)
    camera = _model(top.sub("camera"), CAMERAS, "pinhole")
    origin = _render_origin(render, camera)
    render.finish()
    materials = top.sub("materials")
    names = list(materials.table)
    if not names:
        raise materials.error("expected at least one material", None)
    material_table = MaterialTable(names, [_model(materials.sub(name), KINDS) for name in names])
    shape_list = top.raw("shapes", None)
    if not isinstance(shape_list, list) or not shape_list:
        raise top.error("expected a non-empty array of tables ([[shapes]])", "shapes")
    light_list = top.raw("lights", [])
    if not isinstance(light_list, list):
        raise top.error("expected an array of tables ([[lights]])", "lights")
    lights = [_model(top.reader(table, f"lights[{i}]"), LIGHTS).translated(-origin)
              for i, table in enumerate(light_list)]
    environments = [i for i, light in enumerate(lights) if light.hit_by_escaping_rays]
    if len(environments) > 1:
        raise top.error(f"at most one environment light is supported, got {len(environments)} "
                        f"(lights{environments})", "lights")
    top.finish()
    mesh, shape_names, emitters = _shapes(top, shape_list, names, origin)
    camera = camera.translated(-origin)
    # Lights at infinity: their power (for light selection) is what crosses the geometry's bounding sphere;
    # light tracing and BDPT start their rays on a disk outside a sphere that also holds a thin lens.
    lo, hi = mesh.bounds()
    scene_radius = 0.5 * float(np.linalg.norm(hi - lo))
    if camera.lens_radius > 0:
        lo = np.minimum(lo, camera.position - camera.lens_radius)
        hi = np.maximum(hi, camera.position + camera.lens_radius)
    light_set = LightSet(emitters + lights, mesh, scene_radius=scene_radius, disk_center=0.5 * (lo + hi),
                         disk_radius=0.5 * float(np.linalg.norm(hi - lo)))
    return Scene(camera=camera, mesh=mesh, materials=material_table, lights=light_set, shape_names=shape_names,
                 source=source, render_spp=render_spp, fingerprint=fingerprint(data, top.files), origin=origin,
                 traversal=traversal)


def _check_extent(top: Fields, vertices: np.ndarray) -> None:
    """Refuse geometry (render-space ``vertices``) that float32 tracing cannot render faithfully around the
    render origin (measured on the Cornell box: right from 1e-8 to 1e12 times its size, 7% dark at 1e-9,
    wrong beyond 1e12)."""
    reach = float(np.abs(vertices).max())
    extent = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    if reach > MAX_RENDER_COORDINATE or extent < MIN_SCENE_EXTENT:
        raise top.error(f"the geometry spans {extent:.3g} scene units and reaches {reach:.3g} from the render origin "
                        f"(the camera unless [render] origin is set); pathspace renders geometry of extent >= "
                        f"{MIN_SCENE_EXTENT:g} within {MAX_RENDER_COORDINATE:g} of that origin (float32 tracing): "
                        "rescale the scene (transform.scale) or set [render] origin near it", "shapes")


def _render_origin(render: Fields, camera) -> np.ndarray:
    """The world point that becomes the origin of render space: ``[render] origin``, "camera" (default:
    the camera's position, like pbrt-v4's camera-world space) or a point [x, y, z]."""
    if isinstance(render.raw("origin", "camera"), str):
        render.string("origin", "camera", choices=("camera",))
        return camera.position.astype(np.float64)
    return render.point("origin")


def fingerprint(data: dict, files: list[Path]) -> str:
    """A hash of a scene description and of every file it loads (SHA-256, hexadecimal): equal for scenes
    that render the same image."""
    digest = hashlib.sha256(json.dumps(data, sort_keys=True, default=str).encode())
    for path in sorted(set(files)):
        digest.update(str(path.name).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def _shapes(top: Fields, shape_list: list, material_names: list[str], origin: np.ndarray):
    """The mesh of all shapes (in render space: world minus ``origin``), their names, and the area lights of
    those that emit."""
    vertices, indices, material_ids, shape_ids, names, emitters = [], [], [], [], [], []
    offset = triangle_offset = 0
    for i, table in enumerate(shape_list):
        shape = top.reader(table, f"shapes[{i}]")
        name = shape.string("name", f"shapes[{i}]")
        if name != f"shapes[{i}]":
            shape.path = f"shapes[{i}] ({name!r})"
        v, f = _shape_geometry(shape)
        material = shape.string("material")
        if material not in material_names:
            raise shape.error(f"unknown material {material!r} (defined: {', '.join(material_names)})", "material")
        emitter = shape.sub("emitter", None)
        if emitter is not None:
            emitters.append(AreaLight.from_fields(emitter).on(triangle_offset + np.arange(len(f))))
        shape.finish()
        vertices.append(v)
        indices.append(f + offset)
        material_ids.append(np.full(len(f), material_names.index(material)))
        shape_ids.append(np.full(len(f), i))
        names.append(name)
        offset += len(v)
        triangle_offset += len(f)
    vertices = np.concatenate(vertices) - origin
    _check_extent(top, vertices)
    mesh = TriangleMesh(vertices, np.concatenate(indices), np.concatenate(material_ids), np.concatenate(shape_ids))
    return mesh, names, emitters


def _shape_geometry(shape: Fields) -> tuple[np.ndarray, np.ndarray]:
    v, f = SHAPES[shape.string("type", choices=SHAPES)](shape)
    transform = shape.sub("transform", None)
    mirrored = False
    if transform is not None:
        v, mirrored = _apply_transform(transform, v)
    # A mirroring transform reverses the winding; undo that so normals keep facing the same way.
    if shape.boolean("flip_normals", False) != mirrored:
        f = f[:, ::-1]
    return v, _check_triangles(shape, v, f, shape.boolean("drop_degenerate", False))


def _apply_transform(fields: Fields, v: np.ndarray) -> tuple[np.ndarray, bool]:
    """The vertices moved by a ``transform`` table (a ``matrix``, or scale, rotate and translate), and whether
    the transform mirrors."""
    matrix = _affine_matrix(fields) if fields.has("matrix") else _scale_rotate_translate(fields)
    fields.finish()
    return v @ matrix[:3, :3].T + matrix[:3, 3], bool(np.linalg.det(matrix[:3, :3]) < 0)


def _affine_matrix(fields: Fields) -> np.ndarray:
    """``matrix``: 4 rows of 4 numbers, an invertible affine map (last row 0, 0, 0, 1), applied to column
    vectors; it replaces scale, rotate and translate."""
    others = [key for key in ("scale", "rotate", "translate") if fields.has(key)]
    if others:
        raise fields.error(f"a matrix replaces scale, rotate and translate; got it with {', '.join(others)}",
                           "matrix")
    matrix = fields.array("matrix", 4)
    if matrix.shape != (4, 4) or np.any(matrix[3] != [0.0, 0.0, 0.0, 1.0]):
        raise fields.error(f"expected 4 rows of 4 numbers, the last [0, 0, 0, 1] (an affine map), got "
                           f"{matrix.tolist()}", "matrix")
    if not abs(np.linalg.det(matrix[:3, :3])) > 0:
        raise fields.error(f"expected an invertible matrix, got {matrix.tolist()}", "matrix")
    return matrix


def _scale_rotate_translate(fields: Fields) -> np.ndarray:
    """The matrix of ``scale``, then ``rotate``, then ``translate``."""
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
    return builtin.transform_matrix(scale, axis, angle, translate)


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
