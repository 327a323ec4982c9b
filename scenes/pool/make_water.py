"""Writes water.ply, the rippled water surface of scenes/pool: a height field over the pool's opening
x, z in [-1, 1] at mean height y = 0, triangulated on a GRID x GRID lattice, normals up (out of the water).

The ripples are a sum of a few sine waves (amplitudes of 6-12 mm, wavelengths of 0.25-0.6 m); they are
what focuses the light into a caustic net on the pool's floor.  Rerun after changing them:

    python scenes/pool/make_water.py
"""
from pathlib import Path

import numpy as np
import trimesh

GRID = 64
# (amplitude in m, wave vector in rad/m (x, z), phase)
WAVES = [(0.012, (9.0, 4.0), 0.3), (0.009, (-5.0, 11.0), 1.7), (0.007, (14.0, -7.0), 4.1), (0.006, (3.0, -19.0), 2.2)]


def height(x: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The water's height above its mean level at (x, z)."""
    return sum(a * np.sin(kx * x + kz * z + phase) for a, (kx, kz), phase in WAVES)


def main() -> None:
    s = np.linspace(-1.0, 1.0, GRID + 1)
    x, z = np.meshgrid(s, s, indexing="ij")
    vertices = np.stack([x.ravel(), height(x, z).ravel(), z.ravel()], axis=1)
    i, j = np.meshgrid(np.arange(GRID), np.arange(GRID), indexing="ij")
    v00 = (i * (GRID + 1) + j).ravel()
    v10, v01, v11 = v00 + GRID + 1, v00 + 1, v00 + GRID + 2
    # Counter-clockwise seen from above (+y): (x, z) -> (x, z + dz) -> (x + dx, z) has normal +y.
    faces = np.concatenate([np.stack([v00, v01, v10], 1), np.stack([v10, v01, v11], 1)])
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert (mesh.face_normals[:, 1] > 0).all()
    mesh.export(Path(__file__).with_name("water.ply"), encoding="binary")


if __name__ == "__main__":
    main()
