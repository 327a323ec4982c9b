"""The random walk every estimator takes: trace, arrive, sample the BSDF, roulette, move on.

Path tracing's camera paths and the camera and light subpaths of light
tracing and BDPT are the same process (Veach 1997, sec. 10.2): from a point
and a direction, find the next surface, sample a direction there from its
BSDF, decide by Russian roulette whether to go on, and carry the throughput
beta = prod f |cos| / (pdf q).  A :class:`Walk` holds the live lanes of such
walks (a :class:`~pathspace.estimators.wavefront.Lanes` with at least the
fields of :data:`WALK_FIELDS`) and their sampler, and offers those steps;
the estimators do their own work between them (emission and next-event
estimation for the path tracer; recording vertices and their reverse
densities for subpaths):

``u = walk.draw()``                    this vertex's numbers, by name (a :class:`Dimensions` layout)
``hits = walk.trace()``                the closest hits of the current rays (depth + 1)
``kept = walk.keep(idx, *arrays)``     only lanes ``idx`` stay (state, sampler, and ``arrays``)
``hit = walk.arrive(hits)``            the surface points reached (:class:`Arrival`)
``alive = walk.scatter(hit, ...)``     throughput, roulette, and the next ray from a BSDF sample

Per lane (``WALK_FIELDS``): ``depth`` segments traced, ``origin`` (3, N)
float32 and ``direction`` (3, N) float32 unit of the current ray (which
leaves a surface from just off it, see :func:`pathspace.vecmath.offset_origin`);
``beta`` (C, N) float64 throughput; ``pdf`` (N,) the solid-angle density of
the current direction (of a delta lobe: its discrete probability); ``delta``
whether it was a delta lobe; and, for walks whose vertex densities matter
(subpaths), ``q``: the survival probability the roulette gave at the vertex
the ray left, as multiple importance sampling sees it (1 for policies that
are not local, see :mod:`pathspace.roulette`).  Walks from the camera under
"throughput" roulette also carry ``eta_scale``, the product of eta^2 over the
refractions so far, which the roulette multiplies into the throughput.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from types import SimpleNamespace

import numpy as np

from .. import _native
from ..bsdfs import BSDFSample, Surface
from ..roulette import RussianRoulette
from ..vecmath import RAY_TMIN, dot
from .wavefront import Lanes, take_lanes

__all__ = ["WALK_FIELDS", "Arrival", "Dimensions", "Walk"]

WALK_FIELDS = ("depth", "origin", "direction", "beta", "pdf", "delta")


class Dimensions:
    """How many uniform numbers a walk draws per vertex, by name, in the order drawn.

    ``Dimensions(light=3, bsdf=3, roulette=1)`` draws 7 numbers per vertex;
    :meth:`split` names their rows.
    """

    def __init__(self, **sizes: int) -> None:
        self.sizes = dict(sizes)
        self.size = sum(self.sizes.values())
        ends = np.cumsum([0] + list(self.sizes.values()))
        self._slices = [(name, slice(int(a), int(b))) for name, a, b in zip(self.sizes, ends[:-1], ends[1:])]

    def split(self, u: np.ndarray) -> SimpleNamespace:
        """The rows of ``u`` (size, N) by name."""
        return SimpleNamespace(**{name: u[rows] for name, rows in self._slices})

    def __add__(self, other: "Dimensions") -> "Dimensions":
        return Dimensions(**self.sizes, **other.sizes)


@dataclass
class Arrival:
    """Where the current rays hit surfaces: ``prim`` (N,) triangles, ``t`` distances, points ``p`` and unit
    geometric normals ``normal`` (3, N) float32, ray offsets ``eps``, ``cos`` = dot(normal, -direction)
    (N,) float32 and ``direction`` (3, N) of arrival."""

    prim: np.ndarray
    t: np.ndarray
    p: np.ndarray
    normal: np.ndarray
    eps: np.ndarray
    cos: np.ndarray
    direction: np.ndarray
    material: np.ndarray

    @cached_property
    def surface(self) -> Surface:
        """The shading frame seen from the arriving ray."""
        return Surface.facing(self.normal, self.direction, self.cos)

    def keep(self, indices: np.ndarray) -> "Arrival":
        """The arrivals of lanes ``indices``."""
        return Arrival(*take_lanes(indices, *(getattr(self, name) for name in
                                              ("prim", "t", "p", "normal", "eps", "cos", "direction", "material"))))


class Walk:
    """Live lanes of random walks through ``scene``, their sampler, and the steps they take.

    ``dims``: the numbers drawn per vertex (with ``bsdf`` (3) and
    ``roulette`` (1) among them); ``transport``: "radiance" for walks from
    the camera, "importance" for walks from lights (refraction differs);
    ``rr_scale`` (N,) or None: what the roulette multiplies the throughput by
    before reading it (the inverse of a light subpath's starting throughput).
    """

    def __init__(self, scene, lanes: Lanes, sampler, roulette: RussianRoulette, dims: Dimensions,
                 transport: str = "radiance") -> None:
        self.scene, self.lanes, self.sampler = scene, lanes, sampler
        self.roulette, self.dims, self.transport = roulette, dims, transport
        self.rays = 0
        self._mis_survival: dict[RussianRoulette, np.ndarray] = {}   # q of every material, per roulette
        if roulette.policy == "throughput" and transport == "radiance" and "eta_scale" not in lanes.fields:
            lanes.add("eta_scale", np.ones(lanes.size))  # the product of eta^2 over the refractions so far

    @property
    def size(self) -> int:
        """Number of live lanes."""
        return self.lanes.size

    def numbers(self) -> np.ndarray:
        """This vertex's uniform numbers for every live lane, (dims.size, N) in the order of :attr:`dims`."""
        return self.sampler.draw(self.dims.size)

    def draw(self) -> SimpleNamespace:
        """This vertex's uniform numbers for every live lane, by name (see :class:`Dimensions`)."""
        return self.dims.split(self.numbers())

    def trace(self):
        """Closest hits (:class:`pathspace.accel.Hits`) of the current rays; depth grows by one segment."""
        lanes = self.lanes
        lanes.depth += 1
        self.rays += lanes.size
        return self.scene.accel.intersect(lanes.origin, lanes.direction, RAY_TMIN, normals=False, threads=1)

    def keep(self, indices: np.ndarray, *arrays: np.ndarray):
        """Keep only lanes ``indices`` (increasing): their state, their sampler, and the per-lane ``arrays``
        (last axis), which are returned compacted."""
        self.lanes.keep(indices)
        self.sampler.keep(indices)
        return tuple(take_lanes(indices, *arrays))

    def arrive(self, prim: np.ndarray, b1: np.ndarray, b2: np.ndarray, t: np.ndarray) -> Arrival:
        """The surface points of hits on triangles ``prim`` at barycentrics ``b1``, ``b2``, distance ``t``."""
        p, normal, eps = self.scene.mesh.hit_geometry(prim, b1, b2)
        direction = self.lanes.direction
        return Arrival(prim, t, p, normal, eps, -dot(normal, direction), direction, self.scene.mesh.material.take(prim))

    def split(self, indices: np.ndarray) -> "Walk":
        """The lanes ``indices`` (with their sampler) leave for a walk of their own."""
        return Walk(self.scene, self.lanes.split(indices), self.sampler.split(indices), self.roulette, self.dims,
                    self.transport)

    def extend(self, other: "Walk") -> None:
        """The lanes (and sampler) of ``other`` join this walk."""
        self.lanes.extend(other.lanes)
        self.sampler.extend(other.sampler)
        self.rays += other.rays

    def survival(self, hit: Arrival, sample: BSDFSample, weight: np.ndarray | None = None) -> np.ndarray | None:
        """Roulette's survival probabilities at ``hit`` for the BSDF ``sample`` there (whose ``weight`` the
        throughput takes, unless another is given), or None (all survive)."""
        roulette, lanes = self.roulette, self.lanes
        throughput = None
        if roulette.policy == "throughput":
            throughput = lanes.beta * (sample.weight if weight is None else weight)
            if "rr_scale" in lanes.fields:     # light subpaths: relative to the ray leaving the light
                throughput = throughput * lanes.rr_scale
            if self.transport == "radiance":   # undo the 1 / eta^2 of refractions (see pathspace.roulette)
                scale = lanes.eta_scale if sample.eta is None else lanes.eta_scale * sample.eta * sample.eta
                throughput = throughput * scale
        materials = self.scene.materials
        return roulette.survival(lanes.depth, throughput, materials.albedo.take(hit.material), self._specular(hit))

    def mis_survival(self, hit: Arrival, roulette: RussianRoulette | None = None) -> np.ndarray:
        """q at ``hit`` as multiple importance sampling sees it (N,), under this walk's roulette or another
        (the opposite walk's; see :meth:`pathspace.roulette.RussianRoulette.mis_survival`)."""
        roulette = roulette or self.roulette
        per_material = self._mis_survival.get(roulette)
        if per_material is None:   # q depends on the material alone: once per material, then one gather a vertex
            materials = self.scene.materials
            per_material = self._mis_survival[roulette] = roulette.mis_survival(
                materials.albedo, materials.delta if materials.delta.any() else None)
        return per_material.take(hit.material)

    def _specular(self, hit: Arrival) -> np.ndarray | None:
        """Whether the material at each of ``hit``'s lanes is specular (delta), or None if the scene has none."""
        delta = self.scene.materials.delta
        return delta.take(hit.material) if delta.any() else None

    def scatter(self, hit: Arrival, sample: BSDFSample, u_roulette: np.ndarray, survival: np.ndarray | None,
                q_mis: np.ndarray | None = None) -> np.ndarray:
        """Leave ``hit`` along ``sample``: throughput times its weight over the ``survival`` probability
        (None: 1; decided by ``u_roulette`` (1, N)), the sample's direction and density, and q for MIS
        (``q_mis``, or :meth:`mis_survival`) if the lanes keep a ``q``.  Returns a mask of the lanes that go on
        (not absorbed, not terminated by roulette); the caller keeps them.  The throughput, the roulette's
        decision and the next ray's origin are one C pass (``ext/scatter.c``)."""
        lanes = self.lanes
        beta, weight, u = (np.ascontiguousarray(a, np.float64) for a in (lanes.beta, sample.weight, u_roulette[0]))
        geometry = (np.ascontiguousarray(a, np.float32) for a in (hit.p, hit.normal, hit.eps, sample.wi))
        survival = None if survival is None else np.ascontiguousarray(survival, np.float64)
        lanes.beta, alive, lanes.origin = _native.scatter_step(beta, weight, survival, u, *geometry)
        if "q" in lanes.fields:
            lanes.q = self.mis_survival(hit) if q_mis is None else q_mis
        lanes.pdf, lanes.delta, lanes.direction = sample.pdf, sample.delta, sample.wi
        if sample.eta is not None and "eta_scale" in lanes.fields:
            lanes.eta_scale = lanes.eta_scale * sample.eta * sample.eta
        return alive
