"""Growing explicit paths: walks of a given number of vertices from a vertex, and where walks start.

Path-space mutations (:mod:`pathspace.estimators.path_mutations`) regenerate
parts of a path by walks from its kept vertices: toward the camera from a
light-side vertex (``"importance"`` transport) or toward the light from a
camera-side one (``"radiance"``), sampling the BSDF at each vertex reached,
as BDPT's subpaths do (Veach 1997, sec. 10.2) but with a fixed number of
vertices and no roulette.  Perturbations follow the specular lobes of the
path they perturb (``lobes``).  Every walk draws its numbers from
``uniforms(k)`` -> (k,) in a fixed order, so a chain's run is a function of
its stream.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..bsdfs import MaterialLanes, Surface
from ..spectra import RGBColours
from ..vecmath import RAY_TMIN, dot, offset_origin
from .paths import OPTIONS, Paths

__all__ = ["walk", "Uniforms", "bsdf_direction", "emission_direction", "camera_direction", "film_positions",
           "light_points", "lobe_numbers", "unit"]

Uniforms = Callable[[int], np.ndarray]
# The first BSDF number that picks a specular material's reflection (0) or its transmission (the last lobe).
REFLECT, TRANSMIT = 0.0, 1.0 - 2.0 ** -20


def unit(v: np.ndarray) -> np.ndarray:
    """Rows of (3, n) vectors normalised (float64)."""
    v = v.astype(np.float64)
    length = np.sqrt(dot(v, v))
    return v / np.where(length > 0, length, 1.0)


def lobe_numbers(prev: np.ndarray, here: np.ndarray, nxt: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """The BSDF number that makes a specular vertex at ``here`` scatter as it does between ``prev`` and ``nxt``
    (3, n): :data:`REFLECT` where both lie on one side of the surface, else :data:`TRANSMIT`."""
    n = normal.astype(np.float64)
    side = dot(n, prev.astype(np.float64) - here) * dot(n, nxt.astype(np.float64) - here)
    return np.where(side > 0, REFLECT, TRANSMIT)


def bsdf_direction(scene, vertex: dict, arriving: np.ndarray, mode: str, u: np.ndarray, colours) -> np.ndarray:
    """Directions (3, n) float32 sampled from the BSDFs at surface ``vertex`` (fields of
    :meth:`Paths.vertex`) for light or importance arriving along unit ``arriving`` (3, n), with the lanes'
    ``colours`` (dispersion follows the hero wavelength); zero where the sample failed.  ``u`` (3, n)."""
    surface = Surface.facing(vertex["n"], arriving.astype(np.float32))
    sample = MaterialLanes(scene.materials, vertex["material"], colours, OPTIONS).sample(surface, u, mode)
    return np.where(sample.weight.max(axis=0) > 0, sample.wi, np.float32(0))


def emission_direction(scene, vertex: dict, u: np.ndarray) -> np.ndarray:
    """Directions (3, n) float32 leaving light points ``vertex`` with the emission's density (see
    :meth:`pathspace.lights.area.AreaTables.emitted_directions`); ``u`` (2, n)."""
    return scene.lights.area.emitted_directions(vertex["entity"], vertex["n"], u).astype(np.float32)


def camera_direction(scene, raster: np.ndarray) -> np.ndarray:
    """Unit directions (3, n) float32 from the pinhole through film positions ``raster`` (2, n)."""
    camera = scene.camera
    x, y = np.floor(raster[0]), np.floor(raster[1])
    pixels = (y * camera.width + x).astype(np.int64)
    return camera.generate_rays(pixels, np.stack((raster[0] - x, raster[1] - y)))[1]


def film_positions(camera, u: np.ndarray) -> np.ndarray:
    """Film positions (2, n) in raster units, uniform over the film, from ``u`` (2, n)."""
    return np.stack((u[0] * camera.width, u[1] * camera.height))


def light_points(scene, u: np.ndarray) -> tuple[dict, np.ndarray]:
    """Fresh light vertices chosen by power with their emitted directions (BDPT's light-subpath start):
    (vertex fields, directions (3, n) float32); ``u`` (5, n)."""
    e = scene.lights.sample_le(u, RGBColours, "power")
    count = u.shape[1]
    vertex = dict(p=e.point.astype(np.float32), n=e.normal.astype(np.float32), eps=e.epsilon.astype(np.float32),
                  material=np.full(count, -1, np.int64), entity=e.entity.astype(np.int64))
    return vertex, e.direction.astype(np.float32)


def walk(scene, start: dict, direction: np.ndarray, steps: np.ndarray, mode: str, uniforms: Uniforms, colours,
         lobes: np.ndarray | None = None) -> tuple[Paths, np.ndarray]:
    """Walks of ``steps`` (n,) vertices from vertices ``start`` along ``direction`` (3, n), sampling the BSDF (with
    the lanes' ``colours``) at every vertex but the last: (the vertices reached, as slots 0 .. steps-1 of a
    :class:`Paths` whose ``k`` is unused; how many vertices each walk made before it stopped or escaped, (n,)).
    ``lobes`` (n, steps.max()): the first BSDF number of the scattering at each vertex of the walk
    (perturbations), else drawn."""
    count = steps.size
    span = int(steps.max(initial=0))
    out = Paths.empty(count, max(span, 1))
    reached = np.zeros(count, np.int64)
    moving = dot(direction.astype(np.float64), direction.astype(np.float64)) > 0
    origin = offset_origin(start["p"], start["n"], start["eps"], direction)
    direction = direction.copy()
    active = np.flatnonzero((steps > 0) & moving)
    mesh, emitter = scene.mesh, scene.lights.area.emitter_of_triangle
    for step in range(span):
        if not active.size:
            break
        hits = scene.accel.intersect(np.take(origin, active, axis=1), np.take(direction, active, axis=1), RAY_TMIN,
                                     normals=False, threads=1)
        hit = hits.prim >= 0
        active, prim = active[hit], hits.prim[hit]
        p, n, eps = mesh.hit_geometry(prim, hits.u[hit], hits.v[hit])
        vertex = dict(p=p, n=n, eps=eps, material=mesh.material.take(prim).astype(np.int64), entity=emitter.take(prim))
        out.put(active, np.full(active.size, step), vertex)
        reached[active] += 1
        more = np.flatnonzero(steps.take(active) > step + 1)
        if not more.size:
            break
        active = active.take(more)
        here = {name: np.take(value, more, axis=-1) for name, value in vertex.items()}
        u = uniforms(3 * active.size).reshape(3, active.size)
        if lobes is not None:
            u[0] = lobes[active, step]
        wi = bsdf_direction(scene, here, np.take(direction, active, axis=1), mode, u, colours.take(active))
        moving = dot(wi, wi) > 0
        active, wi = active[moving], wi[:, moving]
        here = {name: np.compress(moving, value, axis=-1) for name, value in here.items()}
        direction[:, active] = wi
        origin[:, active] = offset_origin(here["p"], here["n"], here["eps"], wi)
    return out, reached
