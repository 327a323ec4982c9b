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
from ..vecmath import orthonormal_basis

__all__ = ["SHAPES", "MAX_SUBDIVISIONS", "MAX_SEGMENTS", "quad", "box", "sphere", "disk", "transform_matrix"]

# An icosphere of 8 subdivisions has 1.3 million triangles; beyond that memory runs out quickly.
MAX_SUBDIVISIONS = 8
# A disk of 2^20 segments has a million triangles.
MAX_SEGMENTS = 2 ** 20


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


def disk(center: np.ndarray, normal: np.ndarray, radius: float, segments: int) -> tuple[np.ndarray, np.ndarray]:
    """Regular polygon of ``segments`` sides inscribed in the circle of ``radius`` about ``center``, in the
    plane normal to ``normal``: a fan of triangles around the centre, their normals along ``normal``."""
    n = np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)
    s, t = (axis[:, 0] for axis in orthonormal_basis(n[:, None]))  # s x t = n: counter-clockwise about n
    phi = 2.0 * np.pi * np.arange(segments) / segments
    rim = center + radius * (np.cos(phi)[:, None] * s + np.sin(phi)[:, None] * t)
    k = np.arange(segments)
    faces = np.stack((np.zeros(segments, dtype=np.int64), 1 + k, 1 + (k + 1) % segments), axis=1)
    return np.vstack((np.asarray(center, dtype=np.float64)[None], rim)), faces


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
    if v.ndim != 2 or v.shape[1] != 3:
        raise shape.error(f"mesh file {path} has vertices of shape {v.shape}, expected 3 coordinates each", "file")
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


def _disk(shape: Fields) -> tuple[np.ndarray, np.ndarray]:
    """``center`` (default the origin), ``normal`` (default +z), ``radius``, ``segments`` of the polygon
    (default 64)."""
    normal = shape.direction("normal", [0.0, 0.0, 1.0])
    return disk(shape.vector("center", 3, [0.0, 0.0, 0.0]), normal, shape.number("radius", low=0.0, low_open=True),
                shape.integer("segments", 64, low=3, high=MAX_SEGMENTS))


SHAPES: dict[str, Callable[[Fields], tuple[np.ndarray, np.ndarray]]] = {
    "triangles": _triangles, "mesh": _mesh, "quad": _quad, "box": _box, "sphere": _sphere, "disk": _disk}
