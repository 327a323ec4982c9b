"""The shape types of scene files: each reads its own table and returns triangles.

Every reader returns ``(vertices (V, 3) float64, faces (F, 3) int64)`` with
counter-clockwise winding seen from the side the normal points to; closed
shapes have outward normals.  :data:`SHAPES` maps a ``type`` to its reader;
adding a shape type is one function and one entry.  Transforms, normals
flipping and degenerate triangles are handled by the loader for every type.
"""
from __future__ import annotations

from typing import Callable

import numpy as np
import trimesh

from ..fields import Fields

__all__ = ["SHAPES", "MAX_SUBDIVISIONS", "quad", "box", "sphere", "transform_matrix"]

# An icosphere of 8 subdivisions has 1.3 million triangles; beyond that memory runs out quickly.
MAX_SUBDIVISIONS = 8


def quad(corner: np.ndarray, edge_u: np.ndarray, edge_v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The parallelogram corner + s edge_u + t edge_v, s, t in [0, 1]; normal along edge_u x edge_v."""
    vertices = np.array([corner, corner + edge_u, corner + edge_u + edge_v, corner + edge_v], dtype=np.float64)
    return vertices, np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)


def box(center: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned box with the given center and edge lengths (12 triangles, outward normals)."""
    mesh = trimesh.creation.box(extents=size)
    return np.asarray(mesh.vertices, dtype=np.float64) + center, np.asarray(mesh.faces, dtype=np.int64)


def sphere(center: np.ndarray, radius: float, subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """Icosphere (20 * 4**subdivisions triangles, vertices on the sphere, outward normals)."""
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(mesh.vertices, dtype=np.float64) + center, np.asarray(mesh.faces, dtype=np.int64)


def transform_matrix(scale: np.ndarray, axis: np.ndarray, angle_deg: float, translate: np.ndarray) -> np.ndarray:
    """4x4 matrix applying scale, then a rotation of ``angle_deg`` about ``axis``, then translation."""
    matrix = np.diag([*scale, 1.0])
    if angle_deg != 0.0:
        matrix = trimesh.transformations.rotation_matrix(np.radians(angle_deg), axis) @ matrix
    matrix[:3, 3] += translate
    return matrix


def _triangles(shape: Fields) -> tuple[np.ndarray, np.ndarray]:
    """``vertices`` (rows of 3 numbers) and ``triangles`` (rows of 3 vertex indices)."""
    v = shape.array("vertices", 3)
    f = shape.array("triangles", 3, integer=True)
    if f.min() < 0 or f.max() >= len(v):
        raise shape.error(f"vertex indices must lie in [0, {len(v) - 1}], got {f.min()}..{f.max()}", "triangles")
    return v, f


def _mesh(shape: Fields) -> tuple[np.ndarray, np.ndarray]:
    """A mesh ``file`` (OBJ, PLY, ... -- whatever trimesh reads), relative to the scene file."""
    path = shape.file("file", "mesh")
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


def _quad(shape: Fields) -> tuple[np.ndarray, np.ndarray]:
    """``corner``, ``edge_u``, ``edge_v``."""
    return quad(shape.vector("corner", 3), shape.vector("edge_u", 3), shape.vector("edge_v", 3))


def _box(shape: Fields) -> tuple[np.ndarray, np.ndarray]:
    """``center`` (default the origin) and ``size`` (3 numbers > 0)."""
    size = shape.vector("size", 3, low=0.0)
    if np.any(size <= 0):
        raise shape.error(f"expected 3 numbers > 0, got {size.tolist()}", "size")
    return box(shape.vector("center", 3, [0.0, 0.0, 0.0]), size)


def _sphere(shape: Fields) -> tuple[np.ndarray, np.ndarray]:
    """``center`` (default the origin), ``radius``, ``subdivisions`` of the icosphere (default 3)."""
    return sphere(shape.vector("center", 3, [0.0, 0.0, 0.0]), shape.number("radius", low=0.0, low_open=True),
                  shape.integer("subdivisions", 3, low=0, high=MAX_SUBDIVISIONS))


SHAPES: dict[str, Callable[[Fields], tuple[np.ndarray, np.ndarray]]] = {
    "triangles": _triangles, "mesh": _mesh, "quad": _quad, "box": _box, "sphere": _sphere}
