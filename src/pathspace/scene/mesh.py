"""The scene's geometry as one flat triangle mesh, with per-triangle data.

All shapes of a scene are concatenated into a single mesh; each triangle
records the material and the shape it came from.  The arrays estimators need
per hit (first vertex, edges, unit geometric normal, area) are precomputed
once in structure-of-arrays form.
"""
from __future__ import annotations

import numpy as np

__all__ = ["TriangleMesh", "triangle_cross", "RAY_OFFSET_RELATIVE"]

# Rays leave a surface point p along the line through p but start a distance
# epsilon / |cos| from it (epsilon measured along the normal), so they cannot
# re-hit the surface they leave; segments between two surface points end the
# same way short of their far point.  epsilon is this fraction of the largest
# coordinate magnitude of the triangle's vertices: float32 hit points and
# Embree's intersection distances are accurate to a few units in the last
# place of that magnitude (2**-24 relative), and 2**-18 leaves a 64-fold
# margin.  Being relative to each triangle, it keeps renders invariant under
# scaling and is unaffected by geometry far away.
RAY_OFFSET_RELATIVE = 2.0 ** -18


def triangle_cross(vertices: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """(p1 - p0) x (p2 - p0) of each triangle as an (F, 3) float64 array.

    Its direction is the geometric normal (counter-clockwise winding, right-hand
    rule) and its length twice the triangle's area.
    """
    p = vertices[indices]
    return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])


class TriangleMesh:
    """Triangles of a scene: vertices, indices, and per-triangle material and shape ids.

    Attributes
    ----------
    vertices : (V, 3) float64
    indices : (F, 3) uint32
    material : (F,) int32, index into the scene's material table
    shape : (F,) int32, index into the scene's shape list
    table : (13, F) float32, rows p0 (first vertex), e1 = p1 - p0, e2 = p2 - p0,
        the unit geometric normal (right-hand rule) and the ray offset epsilon
        (see RAY_OFFSET_RELATIVE)
    normal : (3, F) float32, a view of the normal rows
    area : (F,) float64
    """

    def __init__(self, vertices: np.ndarray, indices: np.ndarray, material: np.ndarray, shape: np.ndarray) -> None:
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.indices = np.ascontiguousarray(indices, dtype=np.uint32)
        self.material = np.ascontiguousarray(material, dtype=np.int32)
        self.shape = np.ascontiguousarray(shape, dtype=np.int32)
        p = self.vertices[self.indices]
        e1 = p[:, 1] - p[:, 0]
        e2 = p[:, 2] - p[:, 0]
        n = triangle_cross(self.vertices, self.indices)
        double_area = np.linalg.norm(n, axis=1)
        self.area = 0.5 * double_area
        magnitude = np.maximum(np.abs(p).max(axis=(1, 2)), np.finfo(np.float32).tiny)
        # Rows 0-2: p0, 3-5: e1 = p1 - p0, 6-8: e2 = p2 - p0, 9-11: unit normal, 12: ray
        # offset; one gather of this table gives everything a hit needs.
        self.table = np.ascontiguousarray(np.concatenate(
            [p[:, 0], e1, e2, n / double_area[:, None], RAY_OFFSET_RELATIVE * magnitude[:, None]], axis=1).T,
            dtype=np.float32)
        self.normal = self.table[9:12]

    @property
    def triangle_count(self) -> int:
        """Number of triangles."""
        return int(self.indices.shape[0])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounding box (lower, upper corners)."""
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def hit_geometry(self, prim: np.ndarray, b1: np.ndarray, b2: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Points (1-b1-b2) p0 + b1 p1 + b2 p2 and unit geometric normals, (3, N) float32, on triangles
        ``prim``, and their ray offsets epsilon (N,) float32."""
        rows = np.take(self.table, prim, axis=1)
        return rows[0:3] + rows[3:6] * b1 + rows[6:9] * b2, rows[9:12], rows[12]
