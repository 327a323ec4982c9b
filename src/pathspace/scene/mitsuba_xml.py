"""Mitsuba scene XML (0.6 and 3 syntax) read as a pathspace scene.

The file is parsed with expat, so that every element keeps its line; ``$name`` parameters are substituted
(``<default>`` values, overridden by ``parameters``); files older than version 2.0 get the names Mitsuba 3
gives them when it upgrades them (camelCase to snake_case, a diffuse ``diffuse_reflectance`` to
``reflectance``: Mitsuba 3, ``src/core/parser.cpp``, ``upgrade_from_v1``).  The scene is then converted to
the description the TOML loader reads (docs/scene-format.md) and built by :func:`scene_from_dict`, so that
overrides, validation, fingerprints and geometry are those of TOML scenes.

docs/mitsuba.md lists what is read and how each plugin maps, with the parts of the Mitsuba 3 plugin
documentation it follows.  Whatever is outside that subset is reported by element and line, never dropped:

* a feature that changes the image and that pathspace cannot reproduce (a plastic BSDF, a texture, a
  Beckmann roughness, a spot light's linear falloff, a medium, ...) is an error: one :class:`SceneError`
  lists every such element;
* a feature that leaves the expected image unchanged (integrator, sampler, film output format), or
  changes it in a stated way (reconstruction filter, one-sided BSDFs, tessellated spheres and disks,
  smooth vertex normals, the GGX shadowing form, clipping planes that cut geometry), is a warning: one
  :class:`MitsubaWarning` per file lists every such element.
"""
from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any
from xml.parsers import expat

import numpy as np
import trimesh

from ..bsdfs.conductor import ALPHA_RANGE
from ..fields import SceneError
from ..vecmath import orthonormal_basis
from . import shapes
from .mesh import triangle_cross
from .model import Scene
from .toml_loader import scene_from_dict

__all__ = ["MitsubaWarning", "MitsubaConversion", "Element", "load_mitsuba", "convert_mitsuba", "parse_xml",
           "nearest_distance", "NAMED_IORS", "SPHERE_SUBDIVISIONS", "DISK_SEGMENTS"]

# Files older than this use Mitsuba 0.6 names (Mitsuba 3 upgrades them, parser.cpp transform_upgrade).
UPGRADED_BEFORE = (2, 0, 0)
# Tessellation of Mitsuba's analytic spheres and disks (reported with the area they lose).
SPHERE_SUBDIVISIONS = 5
DISK_SEGMENTS = 256
# Deeper nesting than this is refused (no Mitsuba scene needs it; it guards the recursive conversion).
MAX_DEPTH = 64
# Mitsuba 3's named indices of refraction, include/mitsuba/render/ior.h (from Hecht, Optics, 4th ed.).
NAMED_IORS = {
    "vacuum": 1.0, "helium": 1.000036, "hydrogen": 1.000132, "air": 1.000277, "carbon dioxide": 1.00045,
    "water": 1.3330, "acetone": 1.36, "ethanol": 1.361, "carbon tetrachloride": 1.461, "glycerol": 1.4729,
    "benzene": 1.501, "silicone oil": 1.52045, "bromine": 1.661, "water ice": 1.31, "fused quartz": 1.458,
    "pyrex": 1.470, "acrylic glass": 1.49, "polypropylene": 1.49, "bk7": 1.5046, "sodium chloride": 1.544,
    "amber": 1.55, "pet": 1.5750, "diamond": 2.419}
# Mitsuba's defaults (Mitsuba 3 plugin documentation): hdrfilm size, clipping planes, diffuse reflectance.
FILM_SIZE = (768, 576)
NEAR_CLIP, FAR_CLIP = 1e-2, 1e4
DEFAULT_REFLECTANCE = 0.5

_OBJECTS = {"scene", "bsdf", "emitter", "film", "integrator", "medium", "phase", "rfilter", "sampler", "sensor",
            "shape", "texture", "volume", "field"}
_PROPERTIES = {"boolean", "integer", "float", "string", "point", "vector", "rgb", "srgb", "spectrum", "blackbody",
               "transform"}
_UNSUPPORTED_TAGS = {"include": "<include> is not supported: merge the included file into this one",
                     "alias": "<alias> is not supported", "path": "<path> (a resource folder) is not supported"}
_BSDF_HELP = ("pathspace reads diffuse, conductor (as a mirror), roughconductor with GGX, dielectric and twosided "
              "(docs/mitsuba.md)")
_SHAPE_HELP = "pathspace reads obj, ply, rectangle, cube, sphere and disk"
_EMITTER_HELP = "pathspace reads area (in a shape), point, spot, directional and constant"
# Mitsuba meshes and spheres keep their face winding (their normal) under a mirroring to_world, where
# pathspace turns it back; rectangles, cubes and disks turn their shading normal with the transform as
# pathspace does (Mitsuba 3.9, measured with ray_intersect).
_KEEP_WINDING = {"obj", "ply", "sphere"}


class MitsubaWarning(UserWarning):
    """A Mitsuba scene was read with differences that are listed in the message, element by element."""


@dataclass
class Element:
    """One XML element: tag, attributes, the line it starts on, child elements."""

    tag: str
    attrs: dict[str, str]
    line: int
    children: list["Element"] = field(default_factory=list)

    def describe(self) -> str:
        """``line N, <tag type="..." id="..." name="...">`` for messages."""
        attrs = " ".join(f'{key}="{self.attrs[key]}"' for key in ("type", "id", "name") if key in self.attrs)
        return f"line {self.line}, <{self.tag}{' ' + attrs if attrs else ''}>"


@dataclass
class _Transform:
    """A parsed ``<transform>``: its 4x4 matrix, and (origin, target, up or None) when it is one ``<lookat>``."""

    matrix: np.ndarray
    lookat: tuple[np.ndarray, np.ndarray, np.ndarray | None] | None = None


@dataclass
class MitsubaConversion:
    """A Mitsuba XML file converted to a pathspace scene description.

    ``data``: the description (the structure of docs/scene-format.md); ``warnings``: what differs from
    Mitsuba without being an error (each "line N, <element>: ..."); ``where``: the element each part of the
    description came from ("camera", "materials.NAME", "shapes[i]", "lights[i]"); ``clipping``: the sensor's
    (near_clip, far_clip, element), and ``smooth_meshes`` (shape index, element, whether the file has vertex
    normals) of meshes Mitsuba may shade smoothly, for :meth:`check`.
    """

    source: str
    data: dict[str, Any]
    warnings: list[str]
    where: dict[str, str]
    clipping: tuple[float, float, str] | None = None
    smooth_meshes: list[tuple[int, str, bool]] = field(default_factory=list)

    def locate(self, message: str) -> str:
        """A scene error about the description, with the Mitsuba element (and line) it came from."""
        prefix = f"{self.source}: "
        rest = message[len(prefix):] if message.startswith(prefix) else message
        path = rest.split(":", 1)[0]
        keys = [key for key in self.where if path == key or path.startswith((key + ".", key + " "))]
        if not keys:
            return message
        return f"{prefix}{self.where[max(keys, key=len)]}: {rest}"

    def check(self, scene: Scene) -> list[str]:
        """Differences only the built scene shows: clipping planes that cut geometry, meshes Mitsuba shades
        with interpolated vertex normals."""
        notes = []
        camera, mesh = scene.camera, scene.mesh
        if self.clipping is not None:
            near, far, where = self.clipping
            depth = float(np.max((mesh.vertices - camera.position) @ camera.forward))
            if depth > far:
                notes.append(f"{where}: far_clip = {far:g} but geometry reaches {depth:.6g} along the view axis: "
                             "Mitsuba clips it away, pathspace does not")
            reach = near * math.hypot(1.0, *camera.tan_half) + camera.lens_radius
            nearest = nearest_distance(mesh.vertices, mesh.indices, camera.position)
            if nearest < reach:
                notes.append(f"{where}: near_clip = {near:g} but geometry comes within {nearest:.6g} of the "
                             "camera: Mitsuba may clip it away, pathspace does not")
        for index, where, file_normals in self.smooth_meshes:
            if file_normals or _shared_vertices_bend(mesh.indices[mesh.shape == index],
                                                     mesh.normal[:, mesh.shape == index].T):
                source = "the file's vertex normals" if file_normals else "vertex normals it interpolates"
                notes.append(f"{where}: Mitsuba shades this mesh with {source} (face_normals is false); pathspace "
                             "uses face normals: the images differ where the mesh is curved")
        return notes


def load_mitsuba(path: str | Path, *, parameters: dict[str, Any] | None = None,
                 resolution: tuple[int, int] | None = None, spp: int | None = None, **overrides: Any) -> Scene:
    """Load a Mitsuba scene XML file (0.6 or 3 syntax) as a pathspace scene.

    ``parameters`` set ``$name`` values (over the file's ``<default>`` ones); ``resolution``, ``spp`` and
    ``overrides`` act on the converted description as for TOML scenes (keys such as
    ``materials.ID.reflectance``, see :mod:`pathspace.scene.overrides`).  Features pathspace cannot render as
    Mitsuba would raise one :class:`SceneError` listing each by element and line; harmless or bounded
    differences are listed in one :class:`MitsubaWarning` (see the module docstring and docs/mitsuba.md).
    """
    path = Path(path)
    conversion = convert_mitsuba(path, parameters=parameters, resolution=resolution)
    try:
        scene = scene_from_dict(conversion.data, source=str(path), base_dir=path.parent, resolution=resolution,
                                spp=spp, **overrides)
    except SceneError as error:
        raise SceneError(conversion.locate(str(error))) from None
    notes = conversion.warnings + conversion.check(scene)
    if notes:
        warnings.warn(f"{path}: read with {len(notes)} difference(s) from Mitsuba:\n  " + "\n  ".join(notes),
                      MitsubaWarning, stacklevel=2)
    return scene


def convert_mitsuba(path: str | Path, *, parameters: dict[str, Any] | None = None,
                    resolution: tuple[int, int] | None = None) -> MitsubaConversion:
    """The pathspace scene description of a Mitsuba XML file, with what differs from Mitsuba (see
    :func:`load_mitsuba`).  ``resolution`` replaces the film size (fields of view given along the diagonal
    or by a focal length depend on it)."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"{path}: scene file not found")
    root = parse_xml(path)
    return _Converter(str(path), path.parent, parameters or {}, resolution).convert(root)


def parse_xml(path: Path) -> Element:
    """The element tree of an XML file, each element with its line; malformed XML raises a SceneError
    naming the file and line."""
    stack: list[Element] = []
    roots: list[Element] = []
    parser = expat.ParserCreate()

    def start(tag: str, attrs: dict[str, str]) -> None:
        element = Element(tag, attrs, parser.CurrentLineNumber)
        (stack[-1].children if stack else roots).append(element)
        stack.append(element)
        if len(stack) > MAX_DEPTH:
            raise SceneError(f"{path}: {element.describe()}: elements nested deeper than {MAX_DEPTH}")

    parser.StartElementHandler = start
    parser.EndElementHandler = lambda tag: stack.pop()
    try:
        parser.Parse(path.read_bytes(), True)
    except expat.ExpatError as error:
        raise SceneError(f"{path}: line {error.lineno}: not well-formed XML: {expat.ErrorString(error.code)}") \
            from None
    except LookupError as error:  # an encoding declaration Python does not know
        raise SceneError(f"{path}: line 1: {error}") from None
    return roots[0]


def nearest_distance(vertices: np.ndarray, indices: np.ndarray, point: np.ndarray) -> float:
    """The distance from ``point`` to the nearest of the triangles ``vertices[indices]`` (exact; triangles
    whose bounding sphere lies beyond the nearest vertex are skipped)."""
    p = vertices[indices]
    centroid = p.mean(axis=1)
    radius = np.linalg.norm(p - centroid[:, None], axis=2).max(axis=1)
    upper = np.linalg.norm(vertices[indices[:, 0]] - point, axis=1).min()
    near = np.flatnonzero(np.linalg.norm(centroid - point, axis=1) - radius <= upper)
    closest = trimesh.triangles.closest_point(p[near], np.repeat(np.asarray(point)[None], near.size, axis=0))
    return float(np.linalg.norm(closest - point, axis=1).min())


def _shared_vertices_bend(faces: np.ndarray, normals: np.ndarray) -> bool:
    """Whether some vertex is shared by faces of different normals (interpolated normals then differ)."""
    corner_vertex = faces.ravel()
    order = np.argsort(corner_vertex, kind="stable")
    vertex, normal = corner_vertex[order], np.repeat(normals.astype(np.float64), 3, axis=0)[order]
    starts = np.flatnonzero(np.r_[True, vertex[1:] != vertex[:-1]])
    spread = np.maximum.reduceat(normal, starts) - np.minimum.reduceat(normal, starts)
    return bool(spread.max() > 1e-5)


def _snake(name: str) -> str:
    """Mitsuba 3's camel_to_underscore_case: "intIOR" -> "int_ior", "toWorld" -> "to_world"."""
    return re.sub(r"(?<=[a-z])([A-Z]+)", lambda m: "_" + m.group(1).lower(), name)


def _is_object(element: Element) -> bool:
    return element.tag in _OBJECTS or (element.tag == "spectrum" and "type" in element.attrs)


@lru_cache(maxsize=None)
def _sphere_area_kept() -> float:
    """Area of the icosphere Mitsuba spheres become, over the sphere's."""
    v, f = shapes.sphere(np.zeros(3), 1.0, SPHERE_SUBDIVISIONS)
    return float(np.linalg.norm(triangle_cross(v, f), axis=1).sum() / 2 / (4 * np.pi))


def _has_vertex_normals(path: Path) -> bool:
    """Whether a PLY or OBJ file gives vertex normals (Mitsuba shades with them unless face_normals)."""
    if not path.is_file():
        return False
    data = path.read_bytes()
    if path.suffix.lower() == ".ply":
        header = data[:data.find(b"end_header")]
        return re.search(rb"(?m)^property\s+\w+\s+nx\s*$", header) is not None
    return re.search(rb"(?m)^\s*vn\s", data) is not None


class _Props:
    """The parameters of one Mitsuba object element, read by name (as :class:`pathspace.fields.Fields` reads
    a table): property elements, and nested objects and references."""

    def __init__(self, converter: "_Converter", element: Element) -> None:
        self.converter, self.element = converter, element
        self.values: dict[str, Element] = {}
        self.objects: list[tuple[str | None, Element, Element]] = []  # (name, object, where it was given)
        self.used: set[str] = set()
        self.taken: set[int] = set()
        for child in element.children:
            if child.tag == "default":
                continue
            if child.tag in _UNSUPPORTED_TAGS:
                converter.unsupported(child, _UNSUPPORTED_TAGS[child.tag])
            elif child.tag == "ref":
                target = converter.ids.get(child.attrs.get("id", ""))
                if target is None:
                    converter.fail(child, f"unknown reference id {child.attrs.get('id')!r} (ids defined: "
                                          f"{', '.join(sorted(converter.ids)) or 'none'})")
                self.objects.append((child.attrs.get("name"), target, child))
            elif _is_object(child):
                self.objects.append((child.attrs.get("name"), child, child))
            elif child.tag in _PROPERTIES:
                name = child.attrs.get("name")
                if not name:
                    converter.fail(child, "a property needs a name attribute")
                name = converter.upgrade(name, element.attrs.get("type"))
                if name in self.values:
                    converter.fail(child, f"property {name!r} is given twice (also at line {self.values[name].line})")
                self.values[name] = child
            else:
                converter.fail(child, f"unknown element <{child.tag}> in <{element.tag}>")

    def has(self, name: str) -> bool:
        """Whether the property is given."""
        return name in self.values

    def _get(self, name: str, tags: tuple[str, ...]) -> Element | None:
        element = self.values.get(name)
        if element is None:
            return None
        self.used.add(name)
        if element.tag not in tags:
            self.converter.fail(element, f"{name}: expected <{'> or <'.join(tags)}>, got <{element.tag}>")
        return element

    def _value(self, element: Element) -> str:
        if "value" not in element.attrs:
            self.converter.fail(element, "missing value attribute")
        return element.attrs["value"]

    def number(self, name: str, default: float | None = None) -> float:
        """A ``<float>`` (or ``<integer>``); ``default`` None makes it required."""
        element = self._get(name, ("float", "integer"))
        if element is None:
            if default is None:
                self.converter.fail(self.element, f"the parameter {name!r} is required")
            return default
        return self.converter.floats(element, self._value(element), (1,), "a number")[0]

    def integer(self, name: str, default: int) -> int:
        """An ``<integer>``."""
        element = self._get(name, ("integer",))
        if element is None:
            return default
        text = self._value(element).strip()
        if not re.fullmatch(r"[+-]?\d+", text):
            self.converter.fail(element, f"expected an integer, got {text!r}")
        return int(text)

    def boolean(self, name: str, default: bool) -> bool:
        """A ``<boolean>`` (true or false)."""
        element = self._get(name, ("boolean",))
        if element is None:
            return default
        text = self._value(element).strip().lower()
        if text not in ("true", "false"):
            self.converter.fail(element, f"expected true or false, got {text!r}")
        return text == "true"

    def string(self, name: str, default: str | None = None) -> str:
        """A ``<string>``; ``default`` None makes it required."""
        element = self._get(name, ("string",))
        if element is None:
            if default is None:
                self.converter.fail(self.element, f"the parameter {name!r} is required")
            return default
        return self._value(element)

    def triple(self, name: str) -> np.ndarray | None:
        """A ``<point>`` or ``<vector>``: value="x, y, z" (or one number for all three), or x, y, z attributes."""
        element = self._get(name, ("point", "vector"))
        return None if element is None else self.converter.xyz(element, 0.0, ("name",))

    def transform(self, name: str) -> _Transform | None:
        """A ``<transform>``."""
        element = self._get(name, ("transform",))
        return None if element is None else self.converter.transform(element)

    def colour(self, name: str, default: float) -> list[float] | dict:
        """An RGB triple or a sampled spectrum table from ``<rgb>``, ``<srgb>``, ``<spectrum>`` or ``<float>``."""
        where = next((at for given, _, at in self.objects if given == name), None)
        if where is not None:
            self.take_named(name)
            self.converter.unsupported(where, f"{name}: textures are not supported (a constant colour or "
                                              "spectrum is)")
            return [default] * 3
        element = self._get(name, ("rgb", "srgb", "spectrum", "float", "blackbody"))
        return [default] * 3 if element is None else self.converter.colour(element)

    def ior(self, name: str, default: str) -> float:
        """An index of refraction: a ``<float>``, or a ``<string>`` naming one of :data:`NAMED_IORS`."""
        element = self._get(name, ("float", "string"))
        if element is None or element.tag == "string":
            key = (default if element is None else self._value(element)).lower()
            if key not in NAMED_IORS:
                self.converter.fail(element, f"unknown index of refraction {key!r} (known: {', '.join(NAMED_IORS)})")
            return NAMED_IORS[key]
        return self.converter.floats(element, self._value(element), (1,), "a number")[0]

    def take(self, tag: str) -> list[tuple[Element, Element]]:
        """The nested objects (or references) of kind ``tag``: (object, where it was given)."""
        found = [(obj, at) for _, obj, at in self.objects if obj.tag == tag and id(at) not in self.taken]
        self.taken.update(id(at) for _, at in found)
        return found

    def take_named(self, name: str) -> None:
        """Mark the nested object given as parameter ``name`` as handled."""
        self.taken.update(id(at) for given, _, at in self.objects if given == name)

    def finish(self, harmless: dict[str, str] | None = None, others_harmless: str | None = None) -> None:
        """Report every parameter and nested object not read: a warning when ``harmless`` names it (or
        ``others_harmless`` gives a reason for all), else an error."""
        harmless = harmless or {}
        for name, element in self.values.items():
            if name in self.used:
                continue
            reason = harmless.get(name, others_harmless)
            if reason is not None:
                self.converter.warn(element, f"{name} ignored ({reason})")
            else:
                self.converter.unsupported(element, f"parameter {name!r} of <{self.element.tag} type="
                                                    f"\"{self.element.attrs.get('type', '')}\"> is not supported")
        for _, obj, at in self.objects:
            if id(at) not in self.taken:
                self.converter.unsupported(at, f"<{obj.tag}> is not supported here")


class _Converter:
    """One Mitsuba XML file to a pathspace scene description; collects errors and warnings."""

    def __init__(self, source: str, base: Path, parameters: dict[str, Any],
                 resolution: tuple[int, int] | None) -> None:
        self.source, self.base, self.resolution = source, base, resolution
        self.parameters = {str(k): str(v) for k, v in parameters.items()}
        self.legacy = False
        self.ids: dict[str, Element] = {}
        self.errors: list[str] = []
        self.warnings: list[str] = []
        self.where: dict[str, str] = {}
        self.materials: dict[str, dict] = {}
        self.material_line: dict[str, float] = {}
        self.material_of: dict[int, str | None] = {}
        self.bsdfs_used: set[int] = set()
        self.one_sided: list[str] = []
        self.shapes: list[dict] = []
        self.lights: list[dict] = []
        self.camera: dict | None = None
        self.render: dict = {}
        self.clipping: tuple[float, float, str] | None = None
        self.smooth_meshes: list[tuple[int, str, bool]] = []

    # -- reporting ----------------------------------------------------------------------------------

    def fail(self, element: Element | None, message: str):
        """Raise a SceneError about a malformed element (not merely an unsupported one)."""
        where = f"{element.describe()}: " if element is not None else ""
        raise SceneError(f"{self.source}: {where}{message}")

    def unsupported(self, element: Element, message: str) -> None:
        """Record a feature that changes the image and that pathspace cannot render (raised at the end)."""
        self.errors.append(f"{element.describe()}: {message}")

    def warn(self, element: Element, message: str) -> None:
        """Record a harmless or bounded difference from Mitsuba."""
        self.warnings.append(f"{element.describe()}: {message}")

    # -- values ---------------------------------------------------------------------------------------

    def upgrade(self, name: str, plugin: str | None) -> str:
        """A parameter name as Mitsuba 3 reads it (files before version 2.0 are upgraded)."""
        if not self.legacy:
            return name
        name = _snake(name)
        return "reflectance" if plugin == "diffuse" and name == "diffuse_reflectance" else name

    def floats(self, element: Element, text: str, counts: tuple[int, ...], what: str) -> list[float]:
        """Finite numbers separated by commas or spaces, as many as one of ``counts``."""
        tokens = [token for token in re.split(r"[,\s]+", text.strip()) if token]
        try:
            values = [float(token) for token in tokens]
        except ValueError:
            values = []
        if len(values) not in counts or not all(math.isfinite(v) for v in values):
            self.fail(element, f"expected {what}, got {text!r}")
        return values

    def xyz(self, element: Element, default: float, allowed: tuple[str, ...]) -> np.ndarray:
        """x, y, z from value="x, y, z" (or one number for all three) or x/y/z attributes (Mitsuba 3's
        expand_value_to_xyz)."""
        unexpected = set(element.attrs) - {"value", "x", "y", "z", *allowed}
        if unexpected:
            self.fail(element, f"unexpected attribute(s) {', '.join(sorted(unexpected))}")
        if "value" in element.attrs:
            if {"x", "y", "z"} & set(element.attrs):
                self.fail(element, 'cannot mix "value" and "x"/"y"/"z" attributes')
            values = self.floats(element, element.attrs["value"], (1, 3), "1 or 3 numbers")
            return np.array(values * 3 if len(values) == 1 else values, dtype=np.float64)
        return np.array([self.floats(element, element.attrs[c], (1,), "a number")[0] if c in element.attrs
                         else default for c in "xyz"], dtype=np.float64)

    def transform(self, element: Element) -> _Transform:
        """The matrix of a ``<transform>``: its operations applied in order (each multiplies from the left)."""
        matrix, lookat = np.eye(4), None
        operations = element.children
        for op in operations:
            step = np.eye(4)
            tag = op.tag.lower()
            if tag == "translate":
                step[:3, 3] = self.xyz(op, 0.0, ())
            elif tag == "scale":
                step[:3, :3] = np.diag(self.xyz(op, 1.0, ()))
            elif tag == "rotate":
                if "angle" not in op.attrs:
                    self.fail(op, "missing angle attribute")
                axis = self.xyz(op, 0.0, ("angle",))
                if not np.any(axis != 0):
                    self.fail(op, "rotation axis cannot be zero")
                angle = self.floats(op, op.attrs["angle"], (1,), "an angle in degrees")[0]
                step = trimesh.transformations.rotation_matrix(np.radians(angle), axis)
            elif tag == "lookat":
                unexpected = set(op.attrs) - {"origin", "target", "up"}
                if unexpected or not {"origin", "target"} <= set(op.attrs):
                    self.fail(op, "expected origin, target and optionally up attributes")
                origin, target = (np.array(self.floats(op, op.attrs[key], (3,), "3 numbers"))
                                  for key in ("origin", "target"))
                up = np.array(self.floats(op, op.attrs["up"], (3,), "3 numbers")) if "up" in op.attrs else None
                step = self._look_at(op, origin, target, up)
                lookat = (origin, target, up)
            elif tag == "matrix":
                if set(op.attrs) != {"value"}:
                    self.fail(op, "expected a value attribute (9 or 16 numbers, row by row)")
                values = self.floats(op, op.attrs["value"], (9, 16), "9 or 16 numbers (row by row)")
                n = 4 if len(values) == 16 else 3
                step[:n, :n] = np.reshape(values, (n, n))
            else:
                self.fail(op, f"unexpected <{op.tag}> in <transform>")
            matrix = step @ matrix
        return _Transform(matrix, lookat if len(operations) == 1 else None)

    def _look_at(self, element: Element, origin: np.ndarray, target: np.ndarray, up: np.ndarray | None) -> np.ndarray:
        """Mitsuba's look_at: columns left = up x dir, up' = dir x left, dir, origin (a zero up is chosen
        perpendicular to dir, as Mitsuba's coordinate_system does)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            direction = (target - origin) / np.linalg.norm(target - origin)
            if up is None or not np.any(up != 0):
                up = orthonormal_basis(direction[:, None])[0][:, 0]
            left = np.cross(up, direction)
            left /= np.linalg.norm(left)
        if not (np.all(np.isfinite(direction)) and np.all(np.isfinite(left))):
            self.fail(element, "invalid lookat: origin equals target, or up is parallel to the view direction")
        matrix = np.eye(4)
        matrix[:3, 0], matrix[:3, 1], matrix[:3, 2], matrix[:3, 3] = left, np.cross(direction, left), direction, origin
        return matrix

    def colour(self, element: Element) -> list[float] | dict:
        """An RGB triple (linear sRGB) or a sampled spectrum table of the description."""
        text = element.attrs.get("value", "")
        if element.tag == "blackbody":
            self.unsupported(element, "blackbody spectra are not supported (Mitsuba's are not normalised as "
                                      "pathspace's are): give a sampled spectrum")
            return [1.0, 1.0, 1.0]
        if element.tag in ("rgb", "srgb"):
            if element.tag == "srgb" and text.strip().startswith("#"):
                digits = text.strip()[1:]
                if not re.fullmatch(r"[0-9a-fA-F]{6}", digits):
                    self.fail(element, f"expected #rrggbb, got {text!r}")
                values = [int(digits[i:i + 2], 16) / 255.0 for i in (0, 2, 4)]
            else:
                values = self.floats(element, text, (1, 3), "1 or 3 numbers")
                values = values * 3 if len(values) == 1 else values
            if element.tag == "srgb":  # sRGB-encoded (Mitsuba 0.6): decoded with the sRGB transfer function
                from .._colour import colour

                values = [float(v) for v in colour.cctf_decoding(np.asarray(values), function="sRGB")]
            return values
        if element.tag == "float":
            return self.floats(element, text, (1,), "a number") * 3
        if "filename" in element.attrs:
            return self._spectrum_file(element)
        if ":" not in text:
            value = self.floats(element, text, (1,), "a number, or wavelength:value pairs")
            if len(value) == 1:
                return value * 3
        pairs = [token.split(":") for token in re.split(r"\s*,\s*", text.strip()) if token]
        if not pairs or any(len(pair) != 2 for pair in pairs):
            self.fail(element, f"expected wavelength:value pairs (nm), got {text!r}")
        numbers = [self.floats(element, f"{w} {v}", (2,), "wavelength:value pairs") for w, v in pairs]
        return {"wavelengths": [w for w, _ in numbers], "values": [v for _, v in numbers]}

    def _spectrum_file(self, element: Element) -> dict:
        """A spectrum file: lines of "wavelength value", # comments (Mitsuba's .spd format)."""
        path = self.base / element.attrs["filename"]  # an absolute filename replaces the base
        if not path.is_file():
            self.fail(element, f"spectrum file not found: {path}")
        wavelengths, values = [], []
        for number, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            line = line.split("#", 1)[0].strip()
            if line:
                w, v = self.floats(element, line, (2,), f"'wavelength value' on line {number} of {path}")
                wavelengths.append(w)
                values.append(v)
        return {"wavelengths": wavelengths, "values": values}

    # -- the scene ------------------------------------------------------------------------------------

    def convert(self, root: Element) -> MitsubaConversion:
        """The description of the scene ``root``."""
        if root.tag != "scene":
            self.fail(root, "expected a <scene> root element")
        version = root.attrs.get("version")
        if version is None:
            self.fail(root, 'missing version attribute (e.g. version="3.0.0")')
        if not re.fullmatch(r"\d+(\.\d+){0,2}", version.strip()):
            self.fail(root, f"invalid version {version!r}")
        self.legacy = tuple(int(x) for x in (version.strip().split(".") + ["0", "0"])[:3]) < UPGRADED_BEFORE
        self._substitute(root)
        self._index(root)
        top = _Props(self, root)
        sensors = top.take("sensor")
        for sensor, at in sensors[1:]:
            self.warn(at, "only the first sensor is used")
        if sensors:
            self._sensor(sensors[0][0])
        else:
            self.unsupported(root, "no <sensor>: pathspace needs a camera")
        for shape, _ in top.take("shape"):
            self._shape(shape)
        for emitter, _ in top.take("emitter"):
            self._light(emitter)
        for integrator, at in top.take("integrator"):
            settings = ", ".join(f"{k}={v.attrs.get('value')}" for k, v in _Props(self, integrator).values.items())
            self.warn(at, "ignored: pathspace chooses the estimator and its parameters when rendering (pathspace "
                          f"render -e ... -p max_depth=...){'; Mitsuba settings: ' + settings if settings else ''}")
        for bsdf, at in top.take("bsdf"):
            if id(bsdf) not in self.bsdfs_used:
                self.warn(at, "not used by any shape: ignored")
        top.finish()
        if self.one_sided:
            self.warnings.append(
                "pathspace materials reflect on both sides; these Mitsuba BSDFs reflect on the front side only "
                "(black from behind): " + "; ".join(self.one_sided) + ": the images agree unless light reaches "
                "their back sides (wrap them in twosided to state that it may)")
        for notes in (self.warnings, self.errors):
            notes.sort(key=lambda text: int(text.split(",")[0][5:]) if text.startswith("line ") else math.inf)
        if self.errors:
            raise SceneError(f"{self.source}: {len(self.errors)} Mitsuba feature(s) pathspace cannot render as "
                             "Mitsuba would:\n  " + "\n  ".join(self.errors))
        # Materials in document order (as pathspace writes them), whatever order shapes use them in.
        materials = dict(sorted(self.materials.items(), key=lambda item: self.material_line[item[0]]))
        data: dict[str, Any] = {"format": 1, "name": Path(self.source).stem, "camera": self.camera,
                                "materials": materials, "shapes": self.shapes}
        if self.lights:
            data["lights"] = self.lights
        if self.render:
            data["render"] = self.render
        return MitsubaConversion(self.source, data, self.warnings, self.where, self.clipping, self.smooth_meshes)

    def _substitute(self, element: Element) -> None:
        """Replace $name in attribute values, in document order; ``<default>`` defines a name unless the
        caller's parameters do (Mitsuba 3's substitute_parameters; \\$ is a literal $)."""
        if element.tag == "default":
            if not element.attrs.get("name") or "value" not in element.attrs:
                self.fail(element, "expected name and value attributes")
            self.parameters.setdefault(element.attrs["name"], element.attrs["value"])
        for key, value in element.attrs.items():
            if "$" in value:
                element.attrs[key] = re.sub(r"(\\?)\$(\w+)", lambda m: self._parameter(element, m), value)
        for child in element.children:
            self._substitute(child)

    def _parameter(self, element: Element, match: re.Match) -> str:
        if match.group(1):
            return "$" + match.group(2)
        if match.group(2) not in self.parameters:
            self.fail(element, f"undefined parameter ${match.group(2)} (give it with <default> or parameters=)")
        return self.parameters[match.group(2)]

    def _index(self, element: Element) -> None:
        """Every object with an id; a repeated id is an error, as in Mitsuba."""
        for child in element.children:
            if _is_object(child) and "id" in child.attrs:
                previous = self.ids.setdefault(child.attrs["id"], child)
                if previous is not child:
                    self.fail(child, f"duplicate id {child.attrs['id']!r} (first at line {previous.line})")
            self._index(child)

    # -- camera ---------------------------------------------------------------------------------------

    def _sensor(self, element: Element) -> None:
        props = _Props(self, element)
        plugin = element.attrs.get("type", "")
        if plugin not in ("perspective", "thinlens"):
            self.unsupported(element, f"sensor type {plugin!r} is not supported (perspective and thinlens are)")
            return
        width, height = self._film(props.take("film"))
        if self.resolution is not None:
            width, height = (int(x) for x in self.resolution)
        fov, fov_axis = self._fov(props, element, width, height)
        position, look_at, up = self._camera_frame(element, props.transform("to_world"))
        camera: dict[str, Any] = {"type": "pinhole" if plugin == "perspective" else "thinlens",
                                  "position": position, "look_at": look_at, "up": up, "fov": fov,
                                  "fov_axis": fov_axis, "resolution": [width, height]}
        near, far = props.number("near_clip", NEAR_CLIP), props.number("far_clip", FAR_CLIP)
        if not 0 < near < far:
            self.fail(element, f"expected 0 < near_clip < far_clip, got {near:g}, {far:g}")
        self.clipping = (near, far, element.describe())
        harmless = {"shutter_open": "no motion blur", "shutter_close": "no motion blur"}
        if plugin == "thinlens":
            camera["aperture_radius"] = props.number("aperture_radius")
            camera["focus_distance"] = props.number("focus_distance", far)
        else:
            harmless["focus_distance"] = "a pinhole camera has no focal plane"
        for axis in ("x", "y"):
            if props.number(f"principal_point_offset_{axis}", 0.0) != 0.0:
                self.unsupported(element, "an off-centre principal point is not supported")
        samplers = props.take("sampler")
        if len(samplers) > 1:
            self.fail(samplers[1][1], "a sensor can have one sampler")
        if samplers:
            self._sampler(samplers[0][0])
        props.finish(harmless)
        self.camera = camera
        self.where["camera"] = element.describe()

    def _film(self, films: list[tuple[Element, Element]]) -> tuple[int, int]:
        """The film size; a crop window is an error, a reconstruction filter other than a box a warning."""
        if not films:
            return FILM_SIZE
        if len(films) > 1:
            self.fail(films[1][1], "a sensor can have one film")
        element = films[0][0]
        props = _Props(self, element)
        plugin = element.attrs.get("type", "")
        if plugin not in ("hdrfilm", "ldrfilm"):
            self.unsupported(element, f"film type {plugin!r} is not supported (hdrfilm is)")
        elif plugin == "ldrfilm":
            self.warn(element, "pathspace writes linear HDR (EXR) and an sRGB PNG, not a tone-mapped LDR film")
        width, height = props.integer("width", FILM_SIZE[0]), props.integer("height", FILM_SIZE[1])
        crop = [props.integer(f"crop_{k}", default) for k, default in
                (("offset_x", 0), ("offset_y", 0), ("width", width), ("height", height))]
        if crop != [0, 0, width, height]:
            self.unsupported(element, f"a crop window (offset {crop[:2]}, size {crop[2:]}) is not supported")
        filters = props.take("rfilter")
        if not filters:
            self.warn(element, "Mitsuba's default reconstruction filter is a Gaussian; pathspace averages each "
                               "pixel over its area (a box filter): Mitsuba's image is slightly blurred")
        for rfilter, at in filters:
            rprops = _Props(self, rfilter)
            kind, radius = rfilter.attrs.get("type", ""), rprops.number("radius", 0.5)
            if kind != "box" or radius != 0.5:
                self.warn(at, f"reconstruction filter {kind!r} (radius {radius:g}): pathspace averages each pixel "
                              "over its area (a box filter of radius 0.5): Mitsuba's image is slightly blurred")
            rprops.finish(others_harmless="filter shape only")
        props.finish(others_harmless="output format only")
        return width, height

    def _sampler(self, element: Element) -> None:
        props = _Props(self, element)
        if props.has("sample_count"):
            self.render["spp"] = props.integer("sample_count", 4)
        if element.attrs.get("type") != "independent":
            self.warn(element, "pathspace draws independent random numbers: the same expected image, other noise")
        props.finish(others_harmless="sampling pattern only: the same expected image")

    def _fov(self, props: _Props, element: Element, width: int, height: int) -> tuple[float, str]:
        """The field of view and its axis (Mitsuba 3's parse_fov: "diagonal" and ``focal_length`` become a
        horizontal field of view for this film size)."""
        if props.has("fov") and props.has("focal_length"):
            self.fail(element, "give either fov or focal_length, not both")
        diagonal = math.hypot(width, height)
        if props.has("fov"):
            fov, axis = props.number("fov"), props.string("fov_axis", "x").lower()
            if axis not in ("x", "y", "diagonal", "smaller", "larger"):
                self.fail(element, f"fov_axis: expected x, y, diagonal, smaller or larger, got {axis!r}")
            if axis != "diagonal":
                return fov, axis
            tan_diagonal = math.tan(math.radians(fov) / 2)
        else:
            focal = props.values.get("focal_length")
            props.used.add("focal_length")
            text = "50mm" if focal is None else focal.attrs.get("value", "")
            value = self.floats(focal or element, text.strip().removesuffix("mm"), (1,),
                                "a focal length such as 50mm")[0]
            if value <= 0:
                self.fail(focal, f"expected a positive focal length, got {text!r}")
            tan_diagonal = math.hypot(36.0, 24.0) / (2 * value)  # 35 mm film: its diagonal over twice the focal length
        return math.degrees(2 * math.atan(tan_diagonal * width / diagonal)), "x"

    def _camera_frame(self, element: Element, transform: _Transform | None) -> tuple[list, list, list]:
        """Position, look_at and up of a camera whose local frame looks along +z with +y up (image right is
        local -x; Mitsuba 3's perspective sensor): exactly those of a single ``<lookat>``."""
        if transform is None:
            return [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]
        linear = transform.matrix[:3, :3]
        if not np.allclose(linear.T @ linear, np.eye(3), atol=1e-5):
            self.unsupported(element, "scale or shear in the sensor's to_world (Mitsuba refuses scale factors too)")
        elif np.linalg.det(linear) < 0:
            self.unsupported(element, "a mirroring sensor to_world flips the image, which pathspace's cameras "
                                      "cannot do: remove the mirroring scale")
        if transform.lookat is not None:
            origin, target, up = transform.lookat
            up = linear[:, 1] if up is None or not np.any(up != 0) else up
            return origin.tolist(), target.tolist(), up.tolist()
        position = transform.matrix[:3, 3]
        return position.tolist(), (position + linear[:, 2]).tolist(), linear[:, 1].tolist()

    # -- materials ------------------------------------------------------------------------------------

    def _material(self, element: Element) -> str | None:
        """The name of the material of a ``<bsdf>`` (converted on first use)."""
        if id(element) in self.material_of:
            return self.material_of[id(element)]
        self.bsdfs_used.add(id(element))
        self.material_of[id(element)] = None  # until converted: an unsupported BSDF is reported once
        plugin = element.attrs.get("type", "")
        named = element
        if plugin == "twosided":
            props = _Props(self, element)
            inner = props.take("bsdf")
            props.finish()
            if len(inner) != 1:
                self.unsupported(element, "twosided with a different BSDF on each side is not supported"
                                 if inner else "twosided needs one nested bsdf")
                return None
            self.bsdfs_used.add(id(inner[0][0]))
            table = self._bsdf(inner[0][0])
            if table is not None and table["type"] == "dielectric":
                self.unsupported(element, "twosided around a dielectric is not supported (nor by Mitsuba)")
            if "id" not in element.attrs:
                named = inner[0][0]
        else:
            table = self._bsdf(element)
        if table is None:
            return None
        name = self._unique(named.attrs.get("id") or f"{named.attrs.get('type', 'bsdf')}@{named.line}",
                            self.materials)
        self.materials[name] = table
        self.material_line[name] = element.line
        self.material_of[id(element)] = name
        self.where[f"materials.{name}"] = element.describe()
        if plugin != "twosided" and table["type"] != "dielectric":
            self.one_sided.append(f"{name!r} ({element.describe()})")
        return name

    def _bsdf(self, element: Element) -> dict | None:
        """The material table of one (not twosided) BSDF, or None if it is not supported."""
        plugin = element.attrs.get("type", "")
        converters = {"diffuse": self._diffuse, "conductor": self._conductor,
                      "roughconductor": self._roughconductor, "dielectric": self._dielectric}
        if plugin not in converters:
            self.unsupported(element, f"bsdf type {plugin!r} is not supported: {_BSDF_HELP}")
            return None
        props = _Props(self, element)
        table = converters[plugin](props, element)
        props.finish()
        return table

    def _diffuse(self, props: _Props, element: Element) -> dict:
        """diffuse: reflectance (default 0.5)."""
        return {"type": "diffuse", "reflectance": props.colour("reflectance", DEFAULT_REFLECTANCE)}

    def _complex_ior(self, props: _Props, element: Element) -> tuple[Any, Any] | None:
        """eta and k of a conductor, or of its ``material`` preset "none" (eta 0, k 1: a perfect mirror; the
        default of Mitsuba 3, where 0.6 defaulted to copper)."""
        material = props.string("material", "Cu" if self.legacy else "none")
        if props.has("eta") or material == "none":
            if material != "none":
                self.fail(element, "give either eta and k or a material preset, not both")
            return props.colour("eta", 0.0), props.colour("k", 1.0)
        self.unsupported(element, f"conductor preset {material!r}: pathspace does not bundle Mitsuba's measured "
                                  "spectra; give eta and k (rgb or spectrum)")
        return None

    def _no_factor(self, props: _Props, element: Element, name: str) -> None:
        """A ``specular_*`` factor other than 1 has no pathspace counterpart."""
        if props.has(name) and props.colour(name, 1.0) != [1.0, 1.0, 1.0]:
            self.unsupported(element, f"{name} other than 1 is not supported")

    def _conductor(self, props: _Props, element: Element) -> dict:
        """Smooth conductor: only the perfect mirror (eta 0, k 1) maps, to a pathspace mirror whose reflectance
        is ``specular_reflectance``."""
        ior = self._complex_ior(props, element)
        reflectance = props.colour("specular_reflectance", 1.0)
        if ior is not None and ior != ([0.0] * 3, [1.0] * 3):
            self.unsupported(element, "a smooth conductor with Fresnel reflectance (eta, k) is not supported: "
                                      "pathspace's conductor is rough (use roughconductor with GGX)")
        return {"type": "mirror", "reflectance": reflectance}

    def _roughconductor(self, props: _Props, element: Element) -> dict:
        """roughconductor with distribution ggx and an isotropic alpha; warned: Mitsuba's shadowing-masking
        term is the separable G1(wi) G1(wo), pathspace's the height-correlated form."""
        distribution = props.string("distribution", "beckmann").lower()
        if distribution != "ggx":
            self.unsupported(element, f"microfacet distribution {distribution!r} (Mitsuba's default is beckmann): "
                                      "pathspace's conductor is GGX; set distribution to ggx")
        if props.has("alpha_u") or props.has("alpha_v"):
            if props.has("alpha"):
                self.fail(element, "give either alpha or alpha_u and alpha_v")
            alpha, alpha_v = props.number("alpha_u"), props.number("alpha_v")
            if alpha != alpha_v:
                self.unsupported(element, f"anisotropic roughness (alpha_u {alpha:g}, alpha_v {alpha_v:g}) is not "
                                          "supported")
        else:
            alpha = props.number("alpha", 0.1)
        props.boolean("sample_visible", True)  # a sampling choice: pathspace samples visible normals
        self._no_factor(props, element, "specular_reflectance")
        eta, k = self._complex_ior(props, element) or ([0.0] * 3, [1.0] * 3)
        if ALPHA_RANGE[0] <= alpha <= ALPHA_RANGE[1]:  # others are refused when the scene is built
            lam = (math.hypot(1.0, alpha * math.tan(math.radians(80))) - 1) / 2  # Smith's Lambda at 80 degrees
            self.warn(element, "Mitsuba's roughconductor shadows with the separable Smith term G1(wi) G1(wo), "
                               "pathspace's conductor with the height-correlated 1 / (1 + L(wi) + L(wo)): for alpha "
                               f"{alpha:g} they differ by {lam * lam / (1 + lam) ** 2:.2%} at 80 degrees, less nearer "
                               "the normal")
        return {"type": "conductor", "eta": eta, "k": k, "alpha": alpha}

    def _dielectric(self, props: _Props, element: Element) -> dict:
        """dielectric: the relative index int_ior / ext_ior (defaults bk7 and air)."""
        ior = props.ior("int_ior", "bk7") / props.ior("ext_ior", "air")
        for name in ("specular_reflectance", "specular_transmittance"):
            self._no_factor(props, element, name)
        return {"type": "dielectric", "ior": ior}

    # -- shapes and lights ---------------------------------------------------------------------------

    def _shape(self, element: Element) -> None:
        props = _Props(self, element)
        plugin = element.attrs.get("type", "")
        shape: dict[str, Any] = {"name": self._unique(element.attrs.get("id") or f"{plugin}@{element.line}",
                                                     {s["name"] for s in self.shapes})}
        harmless: dict[str, str] = {}
        keep_winding = plugin in _KEEP_WINDING
        if plugin in ("obj", "ply"):
            shape.update(type="mesh", file=props.string("filename"))
            file_normals = _has_vertex_normals(self.base / shape["file"])
            if not props.boolean("face_normals", False):
                self.smooth_meshes.append((len(self.shapes), element.describe(), file_normals))
                keep_winding = not file_normals
            harmless["flip_tex_coords"] = "texture coordinates only"
        elif plugin == "rectangle":
            shape.update(type="quad", corner=[-1.0, -1.0, 0.0], edge_u=[2.0, 0.0, 0.0], edge_v=[0.0, 2.0, 0.0])
        elif plugin == "cube":
            shape.update(type="box", center=[0.0, 0.0, 0.0], size=[2.0, 2.0, 2.0])
        elif plugin == "sphere":
            center = props.triple("center")
            shape.update(type="sphere", center=[0.0] * 3 if center is None else center.tolist(),
                         radius=props.number("radius", 1.0), subdivisions=SPHERE_SUBDIVISIONS)
            self.warn(element, f"tessellated into {20 * 4 ** SPHERE_SUBDIVISIONS} triangles: "
                               f"{1 - _sphere_area_kept():.3%} less area than the sphere")
        elif plugin == "disk":
            shape.update(type="disk", radius=1.0, segments=DISK_SEGMENTS)
            kept = DISK_SEGMENTS * math.sin(2 * math.pi / DISK_SEGMENTS) / (2 * math.pi)
            self.warn(element, f"tessellated into {DISK_SEGMENTS} triangles: {1 - kept:.3%} less area than the disk")
        else:
            self.unsupported(element, f"shape type {plugin!r} is not supported: {_SHAPE_HELP}")
            return
        transform = props.transform("to_world")
        flip = props.boolean("flip_normals", False)
        if transform is not None:
            linear = transform.matrix[:3, :3]
            gram = linear.T @ linear
            if plugin == "sphere" and not np.allclose(gram, np.eye(3) * gram[0, 0], rtol=1e-6, atol=0):
                self.unsupported(element, "a sphere under non-uniform scale or shear (Mitsuba refuses it too)")
            shape["transform"] = {"matrix": transform.matrix.tolist()}
            flip ^= bool(keep_winding and np.linalg.det(linear) < 0)
        if flip:
            shape["flip_normals"] = True
        shape["material"] = self._shape_material(props, element)
        emitters = props.take("emitter")
        for emitter, at in emitters[1:]:
            self.unsupported(at, "a shape can have one emitter")
        if emitters:
            area = self._area(emitters[0][0])
            if area is not None:
                shape["emitter"] = area
        props.finish(harmless)
        self.where[f"shapes[{len(self.shapes)}]"] = element.describe()
        self.shapes.append(shape)

    def _shape_material(self, props: _Props, element: Element) -> str:
        bsdfs = props.take("bsdf")
        for _, at in bsdfs[1:]:
            self.fail(at, "a shape can have one bsdf")
        if bsdfs:
            return self._material(bsdfs[0][0]) or "unsupported"
        name = "default"  # Mitsuba's default BSDF: diffuse, reflectance 0.5
        if name not in self.materials:
            self.materials[name] = {"type": "diffuse", "reflectance": [DEFAULT_REFLECTANCE] * 3}
            self.material_line[name] = math.inf
            self.one_sided.append(f"'default' (Mitsuba's default diffuse BSDF, first used at {element.describe()})")
        return name

    def _area(self, element: Element) -> dict | None:
        """A shape's emitter: area, radiance (default 1)."""
        if element.attrs.get("type") != "area":
            self.unsupported(element, f"emitter type {element.attrs.get('type')!r} in a shape: only area emitters "
                                      "can be attached to shapes")
            return None
        props = _Props(self, element)
        area = {"radiance": props.colour("radiance", 1.0)}
        props.finish({"sampling_weight": "light selection only: the same expected image"})
        return area

    def _light(self, element: Element) -> None:
        props = _Props(self, element)
        plugin = element.attrs.get("type", "")
        if plugin not in ("point", "spot", "directional", "constant"):
            self.unsupported(element, f"emitter type {plugin!r} is not supported here: {_EMITTER_HELP}"
                             + (" (an area emitter belongs in a <shape>)" if plugin == "area" else ""))
            return
        transform = props.transform("to_world")
        matrix = np.eye(4) if transform is None else transform.matrix
        if plugin == "point":
            position = props.triple("position")
            if position is not None and transform is not None:
                self.fail(element, "give either position or to_world, not both")
            light = {"type": "point", "position": (matrix[:3, 3] if position is None else position).tolist(),
                     "intensity": props.colour("intensity", 1.0)}
        elif plugin == "spot":
            position, axis = matrix[:3, 3], matrix[:3, 2] / np.linalg.norm(matrix[:3, 2])
            target = transform.lookat[1] if transform is not None and transform.lookat is not None else position + axis
            cutoff = props.number("cutoff_angle", 20.0)
            beam = props.number("beam_width", cutoff * 3 / 4)
            if beam != cutoff:
                self.unsupported(element, f"beam_width {beam:g} < cutoff_angle {cutoff:g}: Mitsuba's spot falls off "
                                          "linearly in angle, pathspace's smoothly (pbrt-v4's smoothstep); only a hard "
                                          "edge (beam_width = cutoff_angle) maps exactly")
            light = {"type": "spot", "position": position.tolist(), "look_at": target.tolist(),
                     "intensity": props.colour("intensity", 1.0), "cone_angle": cutoff, "falloff_start": cutoff}
        elif plugin == "directional":
            direction = props.triple("direction")
            if direction is not None and transform is not None:
                self.fail(element, "give either direction or to_world, not both")
            light = {"type": "directional", "direction": (matrix[:3, 2] if direction is None else direction).tolist(),
                     "irradiance": props.colour("irradiance", 1.0)}
        else:
            light = {"type": "environment", "radiance": props.colour("radiance", 1.0)}
        props.finish({"sampling_weight": "light selection only: the same expected image"})
        self.where[f"lights[{len(self.lights)}]"] = element.describe()
        self.lights.append(light)

    @staticmethod
    def _unique(name: str, taken) -> str:
        """``name``, or ``name'``, ``name''`` ... if taken."""
        while name in taken:
            name += "'"
        return name
