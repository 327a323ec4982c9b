"""Built-in shapes, tessellated into triangles, and shape transforms.

Every function returns ``(vertices (V, 3) float64, faces (F, 3) int64)`` with
counter-clockwise winding seen from the side the normal points to; closed
shapes have outward normals.
"""
from __future__ import annotations

import numpy as np
import trimesh

__all__ = ["quad", "box", "sphere", "transform_matrix"]


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
