"""A mutation fuzzer of scene files: hypothesis strategies that mutate the repository's scenes.

A *case* is a folder of files -- one scene file and the mesh and spectrum files it may refer to --
built from a seed scene of ``scenes/`` by a few mutations drawn by hypothesis:

- structured mutations of the parsed scene (:func:`mutate_tree` for TOML, :func:`mutate_xml` for the
  element tree of Mitsuba XML): values replaced by other types,
  NaN, infinities, negative, huge or tiny numbers, big integers, strings with unicode or control
  characters; vectors made shorter or longer, arrays emptied or made huge; keys deleted, misspelt or
  added; ``type`` changed to another model's; tables moved to other places; deep nesting; shapes
  replaced by mesh files and colours by spectrum files, both possibly broken (:func:`mesh_files`,
  :func:`spectrum_files`: truncated OBJ/PLY, NaN vertices, out-of-range indices ...);
- text mutations of the written file (:func:`mutate_bytes`): truncation, byte flips, inserted and
  deleted spans, invalid UTF-8.

:func:`check_case` loads a case and asserts the contract of the loaders: a valid scene or a
:class:`pathspace.SceneError` naming the file -- any other exception fails -- and a valid scene
renders an 8x8 image at 1 spp with every estimator asked for, without an exception or a non-finite
pixel, within a time limit.

Formats are entries of :data:`FORMATS` (TOML, Mitsuba XML): a suffix, seed scenes, and how to parse,
mutate and write a scene file; adding a format is one entry.
"""
from __future__ import annotations

import copy
import functools
import json
import math
import re
import signal
import struct
import tempfile
import tomllib
import xml.etree.ElementTree as ET
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
from hypothesis import strategies as st

import pathspace as ps
from pathspace import SceneError
from conftest import scene_dict

ROOT = Path(__file__).resolve().parents[2]
RESOLUTION = (8, 8)
# A case that takes longer than this (load and renders) is reported as a hang.
TIME_LIMIT = 30.0

INTERESTING_NUMBERS = [0, 1, -1, 2, 3, 0.5, -0.0, 1e-7, -1e-7, 0.9999999, 1.0000001, 179.9999, 180, 90, 2 ** 31,
                       2 ** 32 + 1, 2 ** 53, 2 ** 53 + 1, 2 ** 63 - 1, -2 ** 63, 2 ** 64, 10 ** 30, 10 ** 400,
                       5e-324, 1e-310, 1e-45, 1e-30, 3.4e38, 3.5e38, 1e30, 1e29, 1e150, 1e308, -1e308,
                       math.nan, math.inf, -math.inf]
INTERESTING_STRINGS = ["", " ", "x", "\u00e9t\u00e9", "\u540d\u524d", "\u202e\u0000\u0007", "\U0001f4a1" * 3,
                       "../", "/", ".", "nan", "1", "a" * 5000, "D65", "E", "A", "FL2", "D-65", "x", "y",
                       "smaller", "scene.toml", "mesh0.obj", "spectrum0.csv"]
# The type names of every model, so that mutations can swap one model's table for another's.
TYPE_NAMES = ["pinhole", "thinlens", "diffuse", "phong", "mirror", "dielectric", "conductor", "triangles", "mesh",
              "quad", "box", "sphere", "point", "spot", "directional", "environment", "Diffuse", "plastic"]
# Field names of the format, added to tables where they do not belong (or where they are missing).
FIELD_NAMES = ["type", "name", "material", "emitter", "transform", "radiance", "two_sided", "reflectance", "ior",
               "eta", "k", "alpha", "diffuse", "specular", "exponent", "position", "look_at", "up", "fov",
               "fov_axis", "resolution", "aperture_radius", "focus_distance", "vertices", "triangles", "file",
               "corner", "edge_u", "edge_v", "center", "size", "radius", "subdivisions", "flip_normals",
               "drop_degenerate", "scale", "rotate", "axis", "angle", "translate", "intensity", "cone_angle",
               "falloff_start", "direction", "irradiance", "wavelengths", "values", "blackbody", "illuminant",
               "cauchy", "sellmeier", "b", "c", "format", "render", "spp", "origin", "matrix", "normal", "segments",
               "lights", "shapes", "materials",
               "camera", "unknown_field", "\u00e9"]


@dataclass(frozen=True)
class Nested:
    """A value written as ``depth`` nested arrays (or inline tables) around an empty one."""

    depth: int
    tables: bool = False


@dataclass
class Case:
    """One fuzz case: files by name (the scene file and the files it refers to) and the estimators to run."""

    scene: str
    files: dict[str, bytes]
    estimators: tuple[str, ...]
    notes: list[str] = field(default_factory=list)

    def __repr__(self) -> str:
        text = self.files[self.scene].decode("utf-8", "replace")
        others = ", ".join(f"{name} ({len(data)} bytes)" for name, data in self.files.items() if name != self.scene)
        return (f"Case({self.scene}, estimators={self.estimators}, mutations={self.notes}, other files: "
                f"{others or 'none'})\n--- {self.scene} ---\n{text[:4000]}")


# ---------------------------------------------------------------------------------------------
# Writing TOML (every table inline, so that any tree of values has one spelling)

def toml_value(value: Any) -> str:
    """``value`` (bool, int, float, str, list, dict or :class:`Nested`) as a TOML value."""
    if isinstance(value, Nested):
        opening, closing = ("{a = ", "}") if value.tables else ("[", "]")
        return opening * value.depth + ("{}" if value.tables else "") + closing * value.depth
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(str(k))} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"cannot write {type(value).__name__} as TOML")


def dump_toml(data: dict) -> str:
    """A scene dict as TOML text: one ``key = value`` line per top-level key."""
    return "".join(f"{json.dumps(str(key))} = {toml_value(value)}\n" for key, value in data.items())


# ---------------------------------------------------------------------------------------------
# Structured mutations of a tree of dicts, lists and scalars

Path_ = tuple  # a path into a tree: keys and list indices


def node_paths(tree: Any, path: Path_ = ()) -> Iterator[Path_]:
    """Every path of ``tree``, containers and leaves, root first."""
    yield path
    if isinstance(tree, dict):
        for key, value in tree.items():
            yield from node_paths(value, path + (key,))
    elif isinstance(tree, list) and len(tree) <= 64:  # long arrays of numbers: sample a few rows
        for i, value in enumerate(tree):
            yield from node_paths(value, path + (i,))
    elif isinstance(tree, list):
        for i in sorted({0, 1, len(tree) // 2, len(tree) - 1}):
            yield from node_paths(tree[i], path + (i,))


def get(tree: Any, path: Path_) -> Any:
    """The node of ``tree`` at ``path``."""
    for key in path:
        tree = tree[key]
    return tree


def put(tree: Any, path: Path_, value: Any) -> Any:
    """``tree`` with the node at ``path`` replaced by ``value`` (the root is replaced when path is empty)."""
    if not path:
        return value
    get(tree, path[:-1])[path[-1]] = value
    return tree


def interesting_values() -> st.SearchStrategy:
    """Values of every TOML type that parsers and validators get wrong."""
    scalars = st.one_of(st.sampled_from(INTERESTING_NUMBERS), st.sampled_from(INTERESTING_STRINGS), st.booleans(),
                        st.floats(allow_nan=True, allow_infinity=True), st.integers(-2 ** 70, 2 ** 70),
                        st.text(max_size=20))
    small = st.one_of(scalars, st.lists(scalars, max_size=5), st.dictionaries(st.sampled_from(FIELD_NAMES), scalars,
                                                                              max_size=3))
    return st.one_of(
        scalars, small,
        st.just([]), st.just({}), st.just([[]]), st.just([{}]),
        st.lists(st.sampled_from(INTERESTING_NUMBERS), min_size=1, max_size=6),
        st.builds(lambda n, x: [x] * n, st.sampled_from([2, 4, 1000, 100_000]), st.sampled_from([0.0, 1, 0.5, -1])),
        st.builds(lambda n: [[0.0, 0.0, 0.0]] * n, st.sampled_from([1, 2, 50_000])),
        st.builds(Nested, st.sampled_from([5, 100, 3000]), st.booleans()),
    )


@st.composite
def number_change(draw, value: Any) -> Any:
    """A change of a number that keeps it a number (or makes it the other kind of number)."""
    how = draw(st.sampled_from(["mild"] * 4 + ["negate", "scale", "nan", "inf", "zero", "to_float", "to_int", "nudge",
                                                 "huge"]))
    if how == "mild":
        return value * draw(st.sampled_from([0.5, 0.9, 1.1, 2, 10]))
    if how == "negate":
        return -value
    if how == "scale":
        return value * draw(st.sampled_from([1e-30, 1e-6, 1e6, 1e30, 1e300]))
    if how == "nan":
        return math.nan
    if how == "inf":
        return draw(st.sampled_from([math.inf, -math.inf]))
    if how == "zero":
        return draw(st.sampled_from([0, 0.0, -0.0]))
    if how == "to_float":
        return float(value) + draw(st.sampled_from([0.0, 0.5]))
    if how == "to_int":
        return int(value) if math.isfinite(value) else 0
    if how == "nudge":
        return float(np.nextafter(float(value), draw(st.sampled_from([-math.inf, math.inf]))))
    return draw(st.sampled_from([2 ** 63, -2 ** 63 - 1, 10 ** 30, 1e300, 2 ** 53 + 1]))


BULK_FIELDS = {"vertices", "triangles", "wavelengths", "values"}
COLOUR_FIELDS = {"reflectance", "radiance", "intensity", "irradiance", "eta", "k", "diffuse", "specular"}
# Mutation kinds, repeated by weight: those that keep a scene valid more often come more often, so that
# many cases get past the loader into the renderer.
MUTATIONS = ["number"] * 6 + ["mesh_file"] * 3 + ["spectrum_file"] * 2 + [
    "replace", "list", "delete", "add_key", "transplant", "type", "wrap"]


@st.composite
def mutate_tree(draw, tree: Any, donors: list[Any], files: dict[str, bytes], notes: list[str]) -> Any:
    """``tree`` after one structured mutation at a node drawn from it (see the module docstring)."""
    paths = list(node_paths(tree))
    path = draw(st.sampled_from(paths))
    node = get(tree, path)
    kind = draw(st.sampled_from(MUTATIONS))
    notes.append(f"{kind} at {'.'.join(map(str, path)) or '(root)'}")
    if kind == "replace":
        return put(tree, path, draw(interesting_values()))
    if kind == "number":
        numbers = [p for p in paths if isinstance(get(tree, p), (int, float)) and not isinstance(get(tree, p), bool)]
        if draw(st.booleans()):  # half the time a parameter, not one of the many numbers of a mesh or spectrum
            numbers = [p for p in numbers if not set(p) & BULK_FIELDS] or numbers
        if not numbers:
            return tree
        where = draw(st.sampled_from(numbers))
        notes[-1] = f"number at {'.'.join(map(str, where))}"
        return put(tree, where, draw(number_change(get(tree, where))))
    if kind == "list":
        lists = [p for p in paths if isinstance(get(tree, p), list)]
        if not lists:
            return tree
        where = draw(st.sampled_from(lists))
        items = get(tree, where)
        how = draw(st.sampled_from(["drop", "append", "empty", "duplicate", "truncate", "scalar", "reverse"]))
        notes[-1] = f"list {how} at {'.'.join(map(str, where))}"
        if how == "drop" and items:
            del items[draw(st.integers(0, len(items) - 1))]
        elif how == "append":
            items.append(copy.deepcopy(items[-1]) if items and draw(st.booleans()) else draw(interesting_values()))
        elif how == "empty":
            items.clear()
        elif how == "duplicate" and items:
            items.append(copy.deepcopy(draw(st.sampled_from(items))))
        elif how == "truncate":
            del items[draw(st.integers(0, len(items))):]
        elif how == "scalar":
            return put(tree, where, items[0] if items else 0)
        elif how == "reverse":
            items.reverse()
        return tree
    if kind == "delete":
        keyed = [p for p in paths if p]
        if not keyed:
            return tree
        where = draw(st.sampled_from(keyed))
        notes[-1] = f"delete {'.'.join(map(str, where))}"
        del get(tree, where[:-1])[where[-1]]
        return tree
    if kind == "add_key":
        tables = [p for p in paths if isinstance(get(tree, p), dict)]
        where = draw(st.sampled_from(tables))
        key = draw(st.one_of(st.sampled_from(FIELD_NAMES), st.text(min_size=1, max_size=8)))
        notes[-1] = f"add_key {key!r} at {'.'.join(map(str, where))}"
        value = draw(st.one_of(interesting_values(), st.sampled_from(donor_nodes(donors))))
        get(tree, where)[key] = copy.deepcopy(value)
        return tree
    if kind == "transplant":
        return put(tree, path, copy.deepcopy(draw(st.sampled_from(donor_nodes(donors)))))
    if kind == "type":
        typed = [p for p in paths if isinstance(get(tree, p), dict) and "type" in get(tree, p)]
        if not typed:
            return tree
        where = draw(st.sampled_from(typed))
        new = draw(st.sampled_from(TYPE_NAMES))
        notes[-1] = f"type {new!r} at {'.'.join(map(str, where))}"
        get(tree, where)["type"] = new
        return tree
    if kind == "wrap":
        how = draw(st.sampled_from(["list", "unlist", "table"]))
        if how == "list":
            return put(tree, path, [node])
        if how == "unlist":
            return put(tree, path, node[0] if isinstance(node, list) and node else node)
        return put(tree, path, {"value": node})
    if kind == "mesh_file":
        shapes = [p for p in paths if isinstance(get(tree, p), dict) and "material" in get(tree, p)]
        if not shapes:
            return tree
        where = draw(st.sampled_from(shapes))
        name, data = draw(mesh_files(len(files)))
        files[name] = data
        notes[-1] = f"mesh_file {name} at {'.'.join(map(str, where))}"
        shape = get(tree, where)
        replacement = {key: shape[key] for key in ("name", "material", "emitter", "transform") if key in shape}
        return put(tree, where, {**replacement, "type": "mesh", "file": name})
    # spectrum_file: at a colour (3 numbers or a spectrum table) if there is one
    colours = [p for p in paths if p and p[-1] in COLOUR_FIELDS] or paths
    where = draw(st.sampled_from(colours))
    name, data = draw(spectrum_files(len(files)))
    files[name] = data
    notes[-1] = f"spectrum_file {name} at {'.'.join(map(str, where)) or '(root)'}"
    return put(tree, where, {"file": name, **({"scale": 2.0} if draw(st.booleans()) else {})})


def donor_nodes(donors: list[Any]) -> list[Any]:
    """Sub-trees of the donor scenes (tables and arrays), to be moved to other places."""
    return [get(d, p) for d in donors for p in node_paths(d) if p and isinstance(get(d, p), (dict, list))][:400]


# ---------------------------------------------------------------------------------------------
# Mesh and spectrum files, valid and broken

TETRAHEDRON_V = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
TETRAHEDRON_F = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]
VERTEX_VALUES = [math.nan, math.inf, -math.inf, 1e39, 1e30, 0.0, -1e-45, 1e300]
INDEX_VALUES = [-1, 0, 4, 99, 2 ** 31, 2 ** 32, 2 ** 63, -(2 ** 31)]


def obj_text(vertices, faces) -> bytes:
    """An OBJ file (1-based indices)."""
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in vertices]
    lines += ["f " + " ".join(str(i + 1) for i in face) for face in faces]
    return ("\n".join(lines) + "\n").encode()


def ply_ascii(vertices, faces) -> bytes:
    """An ASCII PLY file."""
    head = ["ply", "format ascii 1.0", f"element vertex {len(vertices)}", "property float x", "property float y",
            "property float z", f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header"]
    body = [" ".join(repr(float(c)) for c in v) for v in vertices]
    body += [f"{len(f)} " + " ".join(map(str, f)) for f in faces]
    return ("\n".join(head + body) + "\n").encode()


def ply_binary(vertices, faces) -> bytes:
    """A binary little-endian PLY file (float32 vertices, int32 indices)."""
    head = ("ply\nformat binary_little_endian 1.0\n"
            f"element vertex {len(vertices)}\nproperty float x\nproperty float y\nproperty float z\n"
            f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n").encode()
    body = np.asarray(vertices, dtype="<f4").reshape(-1, 3).tobytes()  # 1e39 and 1e300 become inf
    body += b"".join(struct.pack("<B", len(f)) + struct.pack(f"<{len(f)}i", *[max(-2 ** 31, min(2 ** 31 - 1, i))
                                                                            for i in f]) for f in faces)
    return head + body


def stl_ascii(vertices, faces) -> bytes:
    """An ASCII STL file."""
    lines = ["solid fuzz"]
    for face in faces:
        lines += ["facet normal 0 0 0", "outer loop"] + [f"vertex {vertices[i][0]!r} {vertices[i][1]!r} "
                                                         f"{vertices[i][2]!r}" for i in face if 0 <= i < len(vertices)]
        lines += ["endloop", "endfacet"]
    return ("\n".join(lines + ["endsolid fuzz"]) + "\n").encode()


MESH_WRITERS: dict[str, Callable[[list, list], bytes]] = {
    "obj": obj_text, "ply": ply_ascii, "binary.ply": ply_binary, "stl": stl_ascii}


@st.composite
def mesh_files(draw, number: int) -> tuple[str, bytes]:
    """(name, contents) of a mesh file: a tetrahedron, possibly with broken vertices or faces, in a format
    trimesh reads, possibly mutated as bytes."""
    vertices = copy.deepcopy(TETRAHEDRON_V)
    faces = copy.deepcopy(TETRAHEDRON_F)
    for _ in range(draw(st.sampled_from([0, 0, 1, 2]))):
        how = draw(st.sampled_from(["vertex", "index", "no_faces", "polygon", "degenerate", "no_vertices"]))
        if how == "vertex" and vertices:
            vertices[draw(st.integers(0, len(vertices) - 1))][draw(st.integers(0, 2))] = draw(
                st.sampled_from(VERTEX_VALUES))
        elif how == "index" and faces:
            faces[draw(st.integers(0, len(faces) - 1))][draw(st.integers(0, 2))] = draw(st.sampled_from(INDEX_VALUES))
        elif how == "no_faces":
            faces = []
        elif how == "polygon":
            faces.append([0, 1, 2, 3, 1])
        elif how == "degenerate":
            faces = [[0, 1, 1]]
        else:
            vertices = []
    suffix = draw(st.sampled_from(sorted(MESH_WRITERS)))
    data = MESH_WRITERS[suffix](vertices, faces)
    if draw(st.integers(0, 3)) == 0:
        data = draw(mutate_bytes(data))
    return f"mesh{number}.{suffix}", data


@st.composite
def spectrum_files(draw, number: int) -> tuple[str, bytes]:
    """(name, contents) of a spectrum CSV file, possibly with bad wavelengths or values."""
    rows = [[400.0, 0.5], [500.0, 0.6], [600.0, 0.7], [700.0, 0.8]]
    for _ in range(draw(st.sampled_from([0, 0, 1, 2]))):
        row, column = draw(st.integers(0, 3)), draw(st.integers(0, 1))
        rows[row][column] = draw(st.sampled_from([math.nan, math.inf, -1.0, 0.0, 1e300, 450.0, 700.0, -math.inf]))
    rows = rows[:draw(st.sampled_from([4, 4, 4, 2, 1, 0]))]
    data = ("wavelength,value\n" + "".join(f"{w!r},{v!r}\n" for w, v in rows)).encode()
    if draw(st.integers(0, 3)) == 0:
        data = draw(mutate_bytes(data))
    return f"spectrum{number}.csv", data


# ---------------------------------------------------------------------------------------------
# Byte mutations (any format)

@st.composite
def mutate_bytes(draw, data: bytes) -> bytes:
    """``data`` after one byte-level mutation: truncation, a flipped bit, an inserted, deleted or
    repeated span, or bytes that are not UTF-8."""
    n = len(data)
    at = draw(st.integers(0, n))
    how = draw(st.sampled_from(["truncate", "flip", "insert", "delete", "repeat", "invalid_utf8"]))
    if how == "truncate":
        return data[:at]
    if how == "flip" and n:
        at = min(at, n - 1)
        return data[:at] + bytes([data[at] ^ (1 << draw(st.integers(0, 7)))]) + data[at + 1:]
    if how == "insert":
        tokens = [b"[", b"]", b"{", b"}", b"=", b",", b"\"", b"\n", b"nan", b"-", b"e999", b"0x", b"\x00", b"<", b">"]
        return data[:at] + draw(st.one_of(st.binary(max_size=8), st.sampled_from(tokens))) + data[at:]
    if how == "delete":
        return data[:at] + data[at + draw(st.integers(1, 64)):]
    if how == "repeat":
        return data[:at] + data[at:at + draw(st.integers(1, 64))] * 2 + data[at:]
    return data[:at] + b"\xff\xfe\xc3" + data[at:]


# ---------------------------------------------------------------------------------------------
# Mitsuba XML: mutations of the element tree

XML_TAGS = ["float", "integer", "string", "boolean", "rgb", "spectrum", "point", "vector", "transform", "lookat",
            "translate", "rotate", "scale", "matrix", "ref", "default", "bsdf", "shape", "emitter", "sensor", "film",
            "sampler", "integrator", "texture", "include", "scene", "medium", "unknown"]
XML_TYPES = ["diffuse", "conductor", "roughconductor", "dielectric", "twosided", "plastic", "obj", "ply", "rectangle",
             "cube", "sphere", "disk", "area", "point", "spot", "directional", "constant", "perspective", "thinlens",
             "hdrfilm", "independent", "path", "bogus"]
XML_ATTRIBUTES = ["name", "value", "type", "id", "filename", "version", "origin", "target", "up", "x", "y", "z",
                  "angle", "axis"]
XML_VALUES = ["nan", "inf", "-inf", "-1", "0", "1e309", "1e-320", "1e30", "1e38", "3.5e38", "", " ", "1, 2",
              "1 2 3 4", "0, 0, 0", "1e300, 1e300, 1e300", "nan, 0, 0", "abc", "$missing", "99999999999999999999",
              "true", "-0", "0x10", "1,,2", "\u00e9t\u00e9", "mesh0.obj", "spectrum0.csv", "#ff0000", "1 0 0 0 0 1",
              "0.5, 0.5, 0.5", "2.0.0", "0.6.0", "3.0.0"]
NUMBER = re.compile(r"-?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
XML_MUTATIONS = ["attribute"] * 4 + ["number"] * 6 + ["mesh_file"] * 2 + [
    "delete", "duplicate", "transplant", "tag", "type", "add_attribute", "delete_attribute", "nest", "text"]


def parents(root: ET.Element) -> dict[int, ET.Element]:
    """The parent of every element but the root, by ``id`` of the child."""
    return {id(child): parent for parent in root.iter() for child in parent}


@st.composite
def mutate_xml(draw, root: ET.Element, donors: list[ET.Element], files: dict[str, bytes], notes: list[str]):
    """``root`` after one mutation of an element drawn from it: attribute values replaced (interesting
    strings, numbers changed as in :func:`number_change`), attributes added or deleted, elements deleted,
    duplicated, moved in from another scene, renamed, given another plugin type, nested deeply, given
    text, or a shape replaced by a (possibly broken) mesh file."""
    elements = list(root.iter())
    element = draw(st.sampled_from(elements))
    kind = draw(st.sampled_from(XML_MUTATIONS))
    notes.append(f"{kind} at <{element.tag} {' '.join(f'{k}={v!r}' for k, v in list(element.attrib.items())[:2])}>")
    up = parents(root)
    if kind == "attribute" and element.attrib:
        key = draw(st.sampled_from(sorted(element.attrib)))
        element.set(key, draw(st.one_of(st.sampled_from(XML_VALUES), st.text(max_size=12))))
    elif kind == "number":
        numeric = [(e, k) for e in elements for k, v in e.attrib.items() if NUMBER.search(v)]
        if numeric:
            element, key = draw(st.sampled_from(numeric))
            matches = list(NUMBER.finditer(element.get(key)))
            match = draw(st.sampled_from(matches))
            value = float(match.group()) if any(c in match.group() for c in ".eE") else int(match.group())
            changed = draw(number_change(value))
            text = element.get(key)
            element.set(key, text[:match.start()] + str(changed) + text[match.end():])
            notes[-1] = f"number {key} of <{element.tag}> -> {element.get(key)[:60]!r}"
    elif kind == "mesh_file":
        shapes = [e for e in elements if e.tag == "shape"]
        if shapes:
            shape = draw(st.sampled_from(shapes))
            name, data = draw(mesh_files(len(files)))
            files[name] = data
            shape.set("type", "ply" if name.endswith(".ply") else "obj")
            for child in [c for c in shape if c.tag in ("float", "integer", "boolean", "point", "vector")]:
                shape.remove(child)
            ET.SubElement(shape, "string", name="filename", value=name)
            notes[-1] = f"mesh_file {name} in a <shape>"
    elif kind == "delete" and id(element) in up:
        up[id(element)].remove(element)
    elif kind == "duplicate" and id(element) in up:
        up[id(element)].append(copy.deepcopy(element))
    elif kind == "transplant":
        donor = draw(st.sampled_from([e for d in donors for e in d.iter()][:400]))
        element.append(copy.deepcopy(donor))
    elif kind == "tag":
        element.tag = draw(st.sampled_from(XML_TAGS))
    elif kind == "type":
        element.set("type", draw(st.sampled_from(XML_TYPES)))
    elif kind == "add_attribute":
        element.set(draw(st.sampled_from(XML_ATTRIBUTES)), draw(st.sampled_from(XML_VALUES)))
    elif kind == "delete_attribute" and element.attrib:
        del element.attrib[draw(st.sampled_from(sorted(element.attrib)))]
    elif kind == "nest":
        inner = element
        for _ in range(draw(st.sampled_from([3, 70, 500]))):
            inner = ET.SubElement(inner, draw(st.sampled_from(["transform", "shape", "bsdf", "x"])))
    elif kind == "text":
        element.text = draw(st.sampled_from(["1", "nan", "<", "\u00e9", "x" * 1000]))
    return root


def dump_xml(root: ET.Element) -> str:
    """An element tree as XML text."""
    return ET.tostring(root, encoding="unicode")


def xml_seeds() -> list[tuple[str, str, dict[str, bytes]]]:
    """Mitsuba 3's Cornell box as written in scenes/cornell-box, at 8x8 pixels."""
    root = ET.parse(ROOT / "scenes" / "cornell-box" / "cornell-box-mitsuba3.xml").getroot()
    for element in root.iter("integer"):
        if element.get("name") in ("width", "height"):
            element.set("value", str(RESOLUTION[0] if element.get("name") == "width" else RESOLUTION[1]))
    return [("cornell-box-mitsuba3", dump_xml(root), {})]


# ---------------------------------------------------------------------------------------------
# Formats

@dataclass(frozen=True)
class Format:
    """A scene file format to fuzz: its suffix; its seed scenes (name, text, the files they refer to); how
    to parse a file into a tree, mutate the tree (a strategy like :func:`mutate_tree`) and write it back;
    and the loader under test."""

    suffix: str
    seeds: Callable[[], list[tuple[str, str, dict[str, bytes]]]]
    parse: Callable[[str], Any]
    mutate: Callable[..., st.SearchStrategy]
    dump: Callable[[Any], str]
    load: Callable[..., ps.Scene] = ps.load_scene


def toml_seeds() -> list[tuple[str, str, dict[str, bytes]]]:
    """Every scene of ``scenes/``, at 8x8 pixels."""
    names = sorted(path.parent.name for path in (ROOT / "scenes").glob("*/scene.toml"))
    return [(name, dump_toml(scene_dict(name, RESOLUTION)), {}) for name in names]


FORMATS: dict[str, Format] = {
    "toml": Format(".toml", toml_seeds, tomllib.loads, mutate_tree, dump_toml),
    "xml": Format(".xml", xml_seeds, ET.fromstring, mutate_xml, dump_xml),
}


@functools.cache
def seeds_of(format_name: str) -> list[tuple[str, str, dict[str, bytes]]]:
    """The seed scenes of a format (read once)."""
    return FORMATS[format_name].seeds()


@st.composite
def cases(draw, format_name: str, all_estimators_share: float = 0.25) -> Case:
    """A fuzz case of a format: a seed scene after 1-3 mutations of its tree and sometimes one of its
    bytes; every estimator runs on ``all_estimators_share`` of the cases, pt on the others."""
    fmt = FORMATS[format_name]
    seeds = seeds_of(format_name)
    name, text, seed_files = draw(st.sampled_from(seeds))
    files = dict(seed_files)
    notes = [f"seed {name}"]
    tree = fmt.parse(text)
    donors = [fmt.parse(t) for _, t, _ in seeds]
    for _ in range(draw(st.sampled_from([1, 1, 1, 2, 3]))):
        tree = draw(fmt.mutate(tree, donors, files, notes))
    try:
        data = fmt.dump(tree).encode("utf-8", "surrogatepass")
    except (TypeError, AttributeError, RecursionError):  # a tree the format cannot write (a list as root ...)
        data = text.encode()
        notes.append("unwritable tree; seed kept")
    if draw(st.integers(0, 3)) == 0:
        data = draw(mutate_bytes(data))
        notes.append("bytes mutated")
    everything = draw(st.floats(0, 1)) < all_estimators_share
    return Case("scene" + fmt.suffix, {**files, "scene" + fmt.suffix: data},
                ("pt", "lt", "bdpt") if everything else ("pt",), notes)


# ---------------------------------------------------------------------------------------------
# The contract

class Hang(Exception):
    """A case ran longer than its time limit."""


@contextmanager
def time_limit(seconds: float):
    """Raise :class:`Hang` in the main thread if the block runs longer than ``seconds``."""
    def expire(signum, frame):
        raise Hang(f"the case ran longer than {seconds:g} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def check_case(case: Case, format_name: str, time_limit_seconds: float = TIME_LIMIT) -> str:
    """Load and render a case; return "error" (a clear SceneError) or "rendered".

    Fails (AssertionError, or the exception itself) if the loader raises anything but a SceneError
    naming the scene file, if a loaded scene does not render at 8x8 pixels and 1 spp with each of the
    case's estimators, or renders a non-finite pixel, or if it all takes longer than the time limit.
    """
    fmt = FORMATS[format_name]
    with tempfile.TemporaryDirectory(prefix="pathspace-fuzz-") as folder, time_limit(time_limit_seconds):
        for name, data in case.files.items():
            (Path(folder) / name).write_bytes(data)
        path = Path(folder) / case.scene
        try:
            scene = fmt.load(path)
        except SceneError as error:
            assert str(path) in str(error), f"the error does not name the scene file {path}: {error}"
            return "error"
        if scene.camera.resolution != RESOLUTION:
            scene = fmt.load(path, resolution=RESOLUTION)
        for estimator in case.estimators:
            result = ps.render(scene, estimator, spp=1, seed=1, threads=1)
            assert result.stats["nonfinite"] == 0, f"{estimator}: {result.stats['nonfinite']} non-finite samples"
            assert np.all(np.isfinite(result.image)), f"{estimator}: non-finite pixels"
        return "rendered"
