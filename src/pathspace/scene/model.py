"""The scene model, independent of any file format."""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..accel import Accel
from ..bsdfs import MaterialTable
from ..camera import PinholeCamera
from ..lights import LightSet
from .mesh import TriangleMesh

__all__ = ["Scene", "TRAVERSALS"]

# How rays are traced (see Scene.traversal).
TRAVERSALS = ("watertight", "fast")


@dataclass
class Scene:
    """Everything an estimator needs: geometry, materials, emitters and camera.

    Attributes
    ----------
    camera : the camera (pinhole or thin lens)
    mesh : all triangles, with material and shape ids
    materials : material table
    lights : area lights (emitting triangles) and the other lights
    shape_names : name of each shape (index = ``mesh.shape``)
    source : the file it was loaded from, if any
    render_spp : the samples per pixel its ``[render]`` table asks for (None: the renderer's default)
    fingerprint : a hash of its description and every file it loads (see ``toml_loader.fingerprint``)
    origin : (3,) float64, the world point at the origin of *render space*.  Every position the scene
        holds (mesh vertices, camera, lights) is in render space, world minus ``origin``: geometry is
        traced in float32, whose precision is relative to the magnitude of coordinates, so it is
        re-centred (on the camera by default, like pbrt-v4's camera-world space) before it is rounded.
        Images do not depend on it; add it back to get world positions (:meth:`to_world`).
    traversal : "watertight" (default) or "fast": how its BVH traces rays (``[render] traversal``).  Watertight
        rays never slip between triangles that share an edge; "fast" traces about 1.5x the rays per second
        but lets a ray aimed within rounding of a shared edge pass through it (see :class:`~pathspace.accel.Accel`,
        ``watertight``).  For speed comparisons with renderers that make the same trade (Mitsuba 3).  Choose it
        when loading (``load_scene(path, **{"render.traversal": "fast"})``), so that it is part of the scene's
        ``fingerprint``, which references, resumed renders and cached results go by; ``dataclasses.replace``
        keeps the fingerprint it copies.
    """

    camera: PinholeCamera
    mesh: TriangleMesh
    materials: MaterialTable
    lights: LightSet
    shape_names: list[str]
    source: str | None = None
    render_spp: int | None = None
    fingerprint: str = ""
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    traversal: str = "watertight"

    def __post_init__(self) -> None:
        if self.traversal not in TRAVERSALS:
            raise ValueError(f"traversal: expected one of {', '.join(TRAVERSALS)}, got {self.traversal!r}")

    @cached_property
    def accel(self) -> Accel:
        """The Embree BVH of the mesh, built on first use (queries choose their thread count)."""
        return Accel(self.mesh.vertices.astype(np.float32), self.mesh.indices,
                     watertight=self.traversal == "watertight")

    @cached_property
    def emitter_accel(self) -> Accel:
        """A BVH of the emitting triangles alone; its primitive ids index ``lights.area.triangles``."""
        triangles = self.mesh.indices[self.lights.area.triangles]
        return Accel(self.mesh.vertices.astype(np.float32), np.ascontiguousarray(triangles),
                     watertight=self.traversal == "watertight")

    def __getstate__(self) -> dict:
        """What pickling keeps (a scene shipped to a worker process): everything but the BVHs, which the
        receiving process builds on first use."""
        return {k: v for k, v in self.__dict__.items() if k not in ("accel", "emitter_accel")}

    def to_world(self, points: np.ndarray) -> np.ndarray:
        """World positions (float64) of render-space ``points`` (..., 3)."""
        return np.asarray(points, dtype=np.float64) + self.origin

    def spectral_reasons(self) -> list[str]:
        """Why this scene needs spectral rendering (empty: RGB suffices)."""
        return self.materials.spectral_reasons() + self.lights.spectral_reasons()

    def describe(self) -> str:
        """A short human-readable summary."""
        lo, hi = (self.to_world(corner) for corner in self.mesh.bounds())
        return "\n".join([
            f"scene {self.source or '(in memory)'}",
            f"  {self.mesh.triangle_count} triangles in {len(self.shape_names)} shapes, "
            f"bounds {np.round(lo, 4).tolist()} .. {np.round(hi, 4).tolist()} (world; rendered relative to "
            f"{np.round(self.origin, 4).tolist()}); {self.traversal} traversal",
            f"  {len(self.materials)} materials: {', '.join(self.materials.names)}",
            f"  {self.lights!r}",
            f"  {self.camera!r}",
        ])
