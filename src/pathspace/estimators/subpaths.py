"""Camera and light subpaths for bidirectional estimators, generated over wavefronts.

Each lane of a batch grows one subpath by the shared random walk
(:mod:`pathspace.estimators.walk`; Veach 1997, ch. 10; pbrt-v3's
GenerateCameraSubpath / GenerateLightSubpath).  Vertex i of a subpath
records where it is, the throughput ``beta`` of the subpath up to it
(excluding its own scattering), and two densities in area measure:

``fwd``  the density with which this walk generated it (from vertex i-1),
``rev``  the density with which a walk in the opposite direction would have
         generated it (from vertex i+1), filled in once vertex i+1 has
         sampled its direction.

Both include the Russian-roulette survival probability ``q`` of the vertex
they are generated from when the policy is *local* (a property of the
material and depth at the vertex, not of the walk: the same in both
directions, as in SmallVCM) and the walk that would generate them puts it in
the MIS densities (``RussianRoulette.in_mis``; BDPT's ``mis_roulette``), so
that the reverse densities can be stored once; see :mod:`pathspace.roulette`.
Densities at points at infinity (the environment) are in solid angle; the
density of a vertex generated from infinity is the density on the disk the
rays start from, projected (times |cos| at the vertex).

A specular (delta) vertex x_i samples its next direction with a Dirac delta
whose weight is the chosen lobe's probability P; the walk in the opposite
direction samples x_{i-1} from x_i with the same delta and the same P.  The
deltas cancel in every ratio of strategy densities (Veach 1997, ch. 10;
no strategy joins at x_i), but the geometry around x_i does not: over
projected solid angle, P G(x_i, x_{i+1}) (eta_next / eta_prev)^2 and
P G(x_{i-1}, x_i) are the densities with the deltas left out, the factor
eta^2 being Snell's Jacobian between the projected solid angles on the two
sides of a refraction (Veach 1997, sec. 5.2).  So the direction a walk
leaves a specular vertex by has the MIS density P eta^2 |cos_out| (solid
angle equivalent; :func:`specular_densities`) and the direction back
P |cos_in|.  Leaving the geometry out -- density 0, read as 1, pbrt's
convention -- weighs a path's strategies by the wrong factor
G(x_{i-1}, x_i) / G(x_i, x_{i+1}): a caustic under a glass sphere resting
on the floor then went to the camera walk that finds the light through the
sphere rather than to light tracing, with fireflies.

Vertices of all lanes are stored flat, lane after lane, with CSR offsets, so
that connections gather any (lane, vertex) pair in one array operation
(:meth:`Subpaths.at` gives a view of chosen vertices).  Camera walks that
leave the scene end in a vertex at infinity when there is an environment
(the s = 0 strategy finds it there); light walks report the rays that pass
through a thin lens (the t = 0 strategy).  Every vertex also carries the
uniforms its connections will use (``u``: a light sample's 3 for camera
vertices, a lens sample's 2 for light vertices), drawn with it, so a lane's
random numbers depend on nothing else in the batch.  The numbers each walk
draws are :data:`CAMERA_START`, :data:`LIGHT_START`, :data:`CAMERA_VERTEX`
and :data:`LIGHT_VERTEX`.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Callable

import numpy as np

from ..bsdfs import MaterialLanes, Surface
from ..roulette import RussianRoulette
from ..vecmath import dot, offset_origin
from .base import Counters
from .control import RenderControl
from .pt_fused import walk_vertex
from .walk import WALK_FIELDS, Arrival, Dimensions, Walk
from .wavefront import Lanes, place_lanes

__all__ = ["Subpaths", "Vertices", "LensHits", "SubpathSettings", "SURFACE", "CAMERA", "LIGHT", "SAFETY_VERTICES",
           "CAMERA_START", "LIGHT_START", "CAMERA_VERTEX", "LIGHT_VERTEX", "camera_subpaths", "light_subpaths",
           "stream_light_vertices", "to_area", "area_density", "cos_at", "specular_densities", "reverse_pdf"]

SURFACE, CAMERA, LIGHT = 0, 1, 2
# Subpaths still growing at this many vertices are cut (and counted): only lossless traps get there.
SAFETY_VERTICES = 10_000
FIELDS = ("lane", "index", "p", "n", "eps", "wo", "beta", "fwd", "rev", "g_prev", "delta", "kind", "material",
          "entity", "q", "q_rev", "infinite", "u")
DENSITY_FIELDS = ("fwd", "rev", "g_prev", "q", "q_rev")   # read by MIS weights only: light tracing leaves them out
# The numbers drawn: at the lens (film position, lens point), at the light (light choice, point and
# direction; the lens sample that joins vertex 0 to the camera), and per vertex (the BSDF sample, the
# roulette, and what this vertex's connections use: a light sample, or a lens sample).
CAMERA_START = Dimensions(pixel=2, lens=2)
LIGHT_START = Dimensions(emission=5, connect=2)
CAMERA_VERTEX = Dimensions(bsdf=3, roulette=1, connect=3)
LIGHT_VERTEX = Dimensions(bsdf=3, roulette=1, connect=2)
# How the light subpaths choose their light, and the light samples joined to camera vertices theirs: one choice,
# so that a light sample's origin density (pmf / area) is the light walk's.
LIGHT_SELECTION = "power"
# What the walks keep per lane besides WALK_FIELDS; the last three only for the vertex densities (walks with
# ``densities``): q, and the previous vertex's normal and whether it is at infinity.
_WALK_FIELDS = WALK_FIELDS + ("lane",)
_DENSITY_WALK_FIELDS = ("q", "prev_n", "prev_infinite")
# What _Recorder.add gives the fields it is not given: (leading shape, dtype, value) -- an off-surface vertex.
_DEFAULTS = {"eps": ((), np.float32, 0.0), "wo": ((3,), np.float32, 0.0), "material": ((), np.int64, -1),
             "entity": ((), np.int64, -1), "infinite": ((), bool, False), "delta": ((), bool, False),
             "rev": ((), np.float64, 0.0), "g_prev": ((), np.float64, 0.0), "q": ((), np.float64, 1.0),
             "q_rev": ((), np.float64, 1.0)}
STREAM_CHUNK = 16384  # the fewest vertices stream_light_vertices hands over at once (but vertices 0 and the last)


def cos_at(normal: np.ndarray, w: np.ndarray) -> np.ndarray:
    """|cos| between unit ``w`` and normals (3, N); 1 where the normal is zero (point lights)."""
    return np.where((normal != 0).any(axis=0), np.abs(dot(normal, w)).astype(np.float64), 1.0)


def to_area(pdf_sa: np.ndarray, normal: np.ndarray, w: np.ndarray, dist2: np.ndarray) -> np.ndarray:
    """Solid-angle densities turned into area densities at targets a distance sqrt(dist2) away along unit
    ``w``: pdf |cos| / d^2 with cos between ``w`` and the target's ``normal`` (a zero normal -- a point
    light -- has no cosine factor; Veach 1997, eq. 8.10)."""
    return area_density(pdf_sa, cos_at(normal, w), dist2)


def area_density(pdf_sa: np.ndarray, cos: np.ndarray, dist2: np.ndarray) -> np.ndarray:
    """:func:`to_area` given the target's |cos| (see :func:`cos_at`): pdf |cos| / d^2, 0 where d^2 is not
    positive."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(dist2 > 0, pdf_sa * cos / dist2, 0.0)


def specular_densities(pdf: np.ndarray, delta: np.ndarray, eta: np.ndarray | None, normal: np.ndarray,
                       wi: np.ndarray, cos_in: np.ndarray, pdf_back: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The MIS densities of the directions sampled at specular vertices (module docstring): (the density of
    ``wi`` -- P eta^2 |cos(normal, wi)| where ``delta``, else ``pdf`` --, the density back toward where the
    walk came from -- P |cos_in| where ``delta``, else ``pdf_back``), with P the lobe's probability ``pdf``,
    ``eta`` the relative index the sample crossed (None: 1) and ``cos_in`` the cosine of the arrival;
    ``ext/pt_vertex.c`` computes them so, bit for bit."""
    eta2 = 1.0 if eta is None else eta * eta
    forward = pdf * eta2 * np.abs(dot(normal, wi)).astype(np.float64)
    back = pdf * np.abs(cos_in).astype(np.float64)
    return np.where(delta, forward, pdf), np.where(delta, back, pdf_back)


def reverse_pdf(materials: MaterialLanes, n: np.ndarray, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Solid-angle density with which the materials sample ``wo`` when light arrives from ``wi`` (the
    walk in the opposite direction); ``n`` geometric normals."""
    return materials.eval(Surface.facing(n, -wi), wo)[1]


@dataclass
class Subpaths:
    """Vertices of one kind of subpath (camera or light) for a batch of lanes, flat with CSR offsets.

    Vertices handed over while they are walked (:func:`stream_light_vertices`) have no ``terminated``, and only
    the fields a light tracer reads; past the vertices 0 (one per lane) they are not grouped by lane, and their
    ``offset`` is None.

    Per vertex: ``lane``, ``index`` (position in its subpath), ``p``, ``n``
    (geometric normal; an area light's normal; the lens axis; the direction
    of travel at infinity; zero for point and spot lights), ``eps`` (ray
    offset of its surface), ``wo`` (unit direction toward the previous
    vertex), ``beta`` (C, V), ``fwd``, ``rev``, ``delta``, ``kind`` (SURFACE,
    CAMERA, LIGHT), ``material`` (-1 off surfaces), ``entity`` (the light
    entity of light vertices and of surface vertices on emitters, else -1),
    ``q`` and ``q_rev`` (the survival probability of its own walk and of the
    opposite walk there, as MIS sees them: see :mod:`pathspace.roulette`),
    ``infinite``, ``u`` (its
    connections' uniforms), ``g_prev`` (what turns a solid-angle density of
    leaving the vertex toward its predecessor into an area density there:
    |cos| / d^2 at the predecessor, |cos| alone from a vertex at infinity, 1
    toward one).  ``terminated`` (lanes,): a dispersive interface kept only
    the hero wavelength somewhere on the lane's subpath.  The fields of
    :data:`DENSITY_FIELDS` are None where the walks' settings skip densities.
    """

    offset: np.ndarray
    lane: np.ndarray
    index: np.ndarray
    p: np.ndarray
    n: np.ndarray
    eps: np.ndarray
    wo: np.ndarray
    beta: np.ndarray
    fwd: np.ndarray
    rev: np.ndarray
    g_prev: np.ndarray
    delta: np.ndarray
    kind: np.ndarray
    material: np.ndarray
    entity: np.ndarray
    q: np.ndarray
    q_rev: np.ndarray
    infinite: np.ndarray
    u: np.ndarray
    terminated: np.ndarray

    @property
    def length(self) -> np.ndarray:
        """Vertices per lane."""
        return np.diff(self.offset)

    @property
    def count(self) -> int:
        """Vertices in all."""
        return int(self.offset[-1])

    def at(self, v: np.ndarray) -> "Vertices":
        """A view of vertices ``v`` (flat indices)."""
        return Vertices(self, v)

    @cached_property
    def _specular_before(self) -> np.ndarray:
        """(V + 1,): how many of the flat vertices before each one are specular (delta)."""
        return np.concatenate([[0], np.cumsum(self.delta)])

    def any_specular(self, lane: np.ndarray, first: int, last: np.ndarray) -> np.ndarray:
        """Whether any of vertices ``first`` .. ``last`` (inclusive; none where ``last`` < ``first``) of the
        subpaths of ``lane`` is specular (delta)."""
        start = self.offset.take(lane)
        before = self._specular_before
        return before.take(start + np.maximum(last + 1, first)) > before.take(start + first)


class Vertices:
    """Vertices ``v`` of a :class:`Subpaths`: every per-vertex field (``p``, ``beta``, ``fwd``, ...) is gathered
    at ``v`` on first use; ``keep`` narrows the view."""

    def __init__(self, subpaths: Subpaths, v: np.ndarray, parent: tuple["Vertices", np.ndarray] | None = None) -> None:
        self.subpaths = subpaths
        self.v = v
        self.parent = parent   # (view, positions in it) this view was kept from

    @property
    def size(self) -> int:
        """Number of vertices in the view."""
        return int(self.v.size)

    def __getattr__(self, name: str) -> np.ndarray:
        if name not in FIELDS:
            raise AttributeError(name)
        parent = self.parent
        if parent is not None and name in parent[0].__dict__:
            value = parent[0].__dict__[name].take(parent[1], axis=-1)
        else:
            value = getattr(self.subpaths, name).take(self.v, axis=-1)
        self.__dict__[name] = value
        return value

    def keep(self, k: np.ndarray) -> "Vertices":
        """The vertices at positions ``k`` of this view.  Fields are gathered when used, from this view's if it
        has gathered them: a field used only before the narrowing is never gathered again."""
        return Vertices(self.subpaths, self.v.take(k), (self, k))


@dataclass
class LensHits:
    """Light-walk rays that pass through a thin lens: the lens would be vertex ``index`` of the subpath.

    ``point`` (3, H) float64 on the lens; ``direction`` (3, H) of the ray;
    ``beta`` (C, H) throughput arriving; ``pdf`` (H,) solid-angle density of
    the direction (with q), or the disk density after an infinite light;
    ``distance`` (H,) from the previous vertex (unused after infinite ones).
    """

    lane: np.ndarray
    index: np.ndarray
    point: np.ndarray
    direction: np.ndarray
    beta: np.ndarray
    pdf: np.ndarray
    distance: np.ndarray

    @classmethod
    def concatenate(cls, parts: list[dict], channels: int) -> "LensHits":
        if not parts:
            return cls(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((3, 0)), np.zeros((3, 0), np.float32),
                       np.zeros((channels, 0)), np.zeros(0), np.zeros(0))
        return cls(**{name: np.concatenate([part[name] for part in parts], axis=-1) for name in parts[0]})


@dataclass
class SubpathSettings:
    """What the subpath walks of a batch share."""

    scene: object
    colours: object
    options: dict
    camera_roulette: RussianRoulette
    light_roulette: RussianRoulette
    max_vertices: int
    counters: Counters
    control: RenderControl
    densities: bool = True  # whether to keep the densities MIS weights read (``rev``, and DENSITY_FIELDS)
    kernel: str = "fused"   # where the walks' vertices are taken (see pathspace.estimators.pt_fused.walk_vertex)


class _Recorder:
    """Vertices collected depth by depth (records of the lanes that have them), flattened at the end; or, with
    ``consume``, handed to it record by record and not kept (a record is then final when it is made: only
    walks without densities, whose ``rev`` is never filled in later, stream).  Without ``densities``, records
    hold no :data:`DENSITY_FIELDS` but those given."""

    def __init__(self, consume: Callable[[dict[str, np.ndarray]], None] | None = None, densities: bool = True) -> None:
        self.records: list[dict[str, np.ndarray]] = []
        self.consume = consume
        self.densities = densities

    def add(self, lanes: np.ndarray, index: int, kind: int, **fields: np.ndarray) -> dict:
        """Record vertex ``index`` of ``kind`` for ``lanes``: the given :data:`FIELDS` (``p``, ``n``, ``beta``,
        ``fwd``, ``u`` at least); the others default to an off-surface vertex (no offset, no material, no
        light, q = 1) with nothing before it (``wo``, ``g_prev`` zero)."""
        count = lanes.size
        record = dict(lane=lanes, index=np.full(count, index, dtype=np.int64), kind=np.full(count, kind, dtype=np.int8),
                      **fields)
        for name, (shape, dtype, value) in _DEFAULTS.items():
            if name not in record and (self.densities or name not in DENSITY_FIELDS):
                record[name] = np.full((*shape, count), value, dtype)
        if self.consume is None:
            self.records.append(record)
        else:
            self.consume(record)
        return record

    def flatten(self, lanes: int, terminated: np.ndarray, densities: bool = True) -> Subpaths:
        # Records hold vertices depth by depth, and a lane has one vertex of every index below its length:
        # vertex i of lane l goes to offset[l] + i.  Every field of every record is written there in one C
        # call (place_lanes: one pass over memory, 1.2-1.3x faster than concatenating the records and gathering
        # the result into that order); without ``densities``, DENSITY_FIELDS are left out (None).
        records = self.records
        counts = np.bincount(np.concatenate([record["lane"] for record in records]), minlength=lanes)
        offset = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        positions = [offset.take(record["lane"]) + record["index"] for record in records]
        names = [name for name in FIELDS if densities or name not in DENSITY_FIELDS]
        fields = dict(zip(names, place_lanes(positions, [[record[name] for name in names] for record in records])))
        return Subpaths(offset=offset, terminated=terminated, **{**dict.fromkeys(FIELDS), **fields})


class _Growth:
    """Subpaths growing by the shared walk from vertex 1 on, recording every vertex."""

    def __init__(self, settings: SubpathSettings, walk: Walk, opposite: RussianRoulette, recorder: _Recorder,
                 record: dict, lanes: int) -> None:
        self.settings, self.walk, self.recorder, self.previous = settings, walk, recorder, record
        self.opposite = opposite  # the roulette of walks in the other direction (for the reverse densities)
        # BSDF sample, roulette and reverse density in one C pass, where the scene allows
        self.fused = walk_vertex(settings.scene, settings.colours, walk.roulette, settings.options, walk.dims,
                                 walk.transport, settings.densities, settings.kernel)[0]
        self.terminated = np.zeros(lanes, bool)
        self.position = np.empty(lanes, np.int64)    # of each lane in the previous record (scratch)
        self.lens_hits: list[dict] | None = None   # light walks through a thin lens: rays that hit it
        self.escapes = False                       # camera walks with an environment: vertices at infinity
        self.limit: np.ndarray | None = None       # most vertices per lane (MMLT's strategies), besides max_vertices

    def run(self) -> None:
        """Walk until every subpath has ended or reached ``max_vertices``."""
        walk, settings = self.walk, self.settings
        while walk.size and int(walk.lanes.depth[0]) + 1 < settings.max_vertices:
            settings.control.check()
            if self.limit is not None:
                full = int(walk.lanes.depth[0]) + 1 >= self.limit.take(walk.lanes.lane)
                if full.any():
                    walk.keep(np.flatnonzero(~full))
                    if not walk.size:
                        break
            hits = walk.trace()
            hit = hits.prim >= 0
            every_hit = bool(hit.all())
            if self.lens_hits is not None:
                self._through_lens(hits.t)
            if self.escapes and not every_hit:
                self._at_infinity(np.flatnonzero(~hit))
            prim, b1, b2, t = hits.prim, hits.u, hits.v, hits.t
            if not every_hit:
                prim, b1, b2, t = walk.keep(np.flatnonzero(hit), prim, b1, b2, t)
                if not walk.size:
                    break
            if not self._vertex(walk.arrive(prim, b1, b2, t)):
                break

    def _mis_pdf(self) -> np.ndarray:
        """The density, as MIS sees it, of the current direction (after a delta lobe, the specular density of the
        module docstring), with q."""
        lanes = self.walk.lanes
        return lanes.pdf * lanes.q

    def _vertex(self, arrival: Arrival) -> bool:
        """Record the vertex reached, sample the next direction there, and roulette (False: the walks stop)."""
        walk, settings = self.walk, self.settings
        lanes, table = walk.lanes, settings.scene.materials
        index = int(lanes.depth[0])
        densities = {}
        if settings.densities:
            dist2 = arrival.t.astype(np.float64) ** 2
            with np.errstate(divide="ignore", invalid="ignore"):
                to_area_here = np.where(lanes.prev_infinite, 1.0, dist2)
                fwd = self._mis_pdf() * np.abs(arrival.cos).astype(np.float64) / to_area_here
                g_prev = np.where(lanes.prev_infinite, 1.0, cos_at(lanes.prev_n, lanes.direction) / dist2)
            densities = dict(fwd=fwd, g_prev=g_prev, q=walk.mis_survival(arrival),
                             q_rev=walk.mis_survival(arrival, self.opposite))
        numbers = walk.numbers()
        u = walk.dims.split(numbers)
        emitter = settings.scene.lights.area.emitter_of_triangle
        record = self.recorder.add(lanes.lane, index, SURFACE, p=arrival.p, n=arrival.normal, eps=arrival.eps,
                                   wo=-lanes.direction, beta=lanes.beta, material=arrival.material.astype(np.int64),
                                   entity=emitter.take(arrival.prim), u=u.connect,
                                   delta=table.delta.take(arrival.material), **densities)
        if index + 1 >= settings.max_vertices:
            if settings.max_vertices >= SAFETY_VERTICES:
                settings.counters.truncated += walk.size
            return False
        if self.fused is not None:
            alive, pdf_back = self._fused_scatter(arrival, numbers, densities.get("q"))
        else:
            materials = MaterialLanes(table, arrival.material, settings.colours.take(lanes.lane), settings.options)
            sample = materials.sample(arrival.surface, u.bsdf, walk.transport)
            if settings.densities:   # as ext/pt_vertex.c gives them
                mis_pdf, pdf_back = specular_densities(
                    sample.pdf, sample.delta, sample.eta, arrival.normal, sample.wi, arrival.cos,
                    reverse_pdf(materials, arrival.normal, sample.wi, -lanes.direction))
            if sample.terminated is not None:
                self.terminated[lanes.lane[sample.terminated]] = True
            alive = walk.scatter(arrival, sample, u.roulette, walk.survival(arrival, sample), densities.get("q"))
            if settings.densities:
                lanes.pdf = mis_pdf
        if settings.densities:
            # The previous vertex as the opposite walk would generate it from here (Veach 1997, eq. 10.7).
            pdf_back = pdf_back * densities["q_rev"]
            # The walk's lanes are some of the previous record's: their places there, via a lane -> place map
            # (6x faster than searchsorted on 64k lanes).
            before = self.previous["lane"]
            self.position[before] = np.arange(before.size)
            self.previous["rev"][self.position.take(lanes.lane)] = pdf_back * g_prev
            lanes.prev_n, lanes.prev_infinite = arrival.normal, np.zeros(walk.size, bool)
        self.previous = record
        if not alive.all():
            walk.keep(np.flatnonzero(alive))
        return True

    def _fused_scatter(self, arrival: Arrival, numbers: np.ndarray, q: np.ndarray | None):
        """The BSDF sample, roulette and next ray of :meth:`_vertex` in one C pass (``ext/pt_vertex.c``), bit for
        bit: (which lanes go on, the reverse density of each direction sampled or None without densities); the
        walk's lanes take their next state, and ``q`` as MIS sees it."""
        lanes = self.walk.lanes
        out = self.fused(arrival, lanes, numbers)
        lanes.beta, lanes.origin, lanes.direction, lanes.pdf, lanes.delta = (out.beta, out.origin, out.direction,
                                                                             out.pdf, out.delta)
        if out.eta_scale is not None:
            lanes.eta_scale = out.eta_scale
        if "q" in lanes.fields:
            lanes.q = q
        return out.alive, out.pdf_back

    def _through_lens(self, t_hit: np.ndarray) -> None:
        """Note the rays that pass through a thin lens before hitting anything."""
        lanes = self.walk.lanes
        t_lens, on_lens = self.settings.scene.camera.intersect_lens(lanes.origin, lanes.direction)
        on_lens &= (t_lens < t_hit) & (t_lens > 0)
        k = np.flatnonzero(on_lens)
        if k.size:
            d = np.take(lanes.direction, k, axis=1)
            self.lens_hits.append(dict(
                lane=lanes.lane.take(k), index=np.full(k.size, int(lanes.depth[0]), dtype=np.int64),
                point=np.take(lanes.origin, k, axis=1).astype(np.float64) + d * t_lens.take(k), direction=d,
                beta=np.take(lanes.beta, k, axis=1), pdf=self._mis_pdf().take(k), distance=t_lens.take(k)))

    def _at_infinity(self, k: np.ndarray) -> None:
        """Record the rays ``k`` that left the scene as vertices at infinity on the environment."""
        lanes = self.walk.lanes
        count = k.size
        d = np.take(lanes.direction, k, axis=1)
        self.recorder.add(lanes.lane.take(k), int(lanes.depth[0]), LIGHT, p=np.take(lanes.origin, k, axis=1), n=d,
                          wo=-d, beta=np.take(lanes.beta, k, axis=1), fwd=self._mis_pdf().take(k),
                          g_prev=cos_at(np.take(lanes.prev_n, k, axis=1), d),
                          entity=np.full(count, self.settings.scene.lights.environment_entity, np.int64),
                          infinite=np.ones(count, bool), u=np.zeros((CAMERA_VERTEX.sizes["connect"], count)))


def _walk_lanes(count: int, densities: bool, **state: np.ndarray) -> Lanes:
    """Walk state of ``count`` lanes leaving vertex 0: ``origin``, ``direction``, ``beta``, ``pdf``,
    ``prev_n`` and ``prev_infinite`` (vertex 0's normal and whether it is at infinity; kept, with ``q``, only
    for walks with ``densities``), and any extra fields."""
    fields = _WALK_FIELDS + (_DENSITY_WALK_FIELDS if densities else ())
    fields += tuple(f for f in state if f not in fields + _DENSITY_WALK_FIELDS)
    if densities:
        state = {**state, "q": np.ones(count)}
    return Lanes(fields, depth=np.zeros(count, np.int32), delta=np.zeros(count, bool), lane=np.arange(count),
                 **state)


def camera_subpaths(settings: SubpathSettings, pixels: np.ndarray, sampler, limit: np.ndarray | None = None) -> Subpaths:
    """Camera subpaths through ``pixels``, one lane each, from ``sampler``'s numbers; ``limit``: the most
    vertices of each lane's subpath (besides ``settings.max_vertices``).

    Vertex 0 is the lens point (density 1 / lens area; a pinhole's is a delta
    and is given 1), with throughput 1: the pixel value is the average
    radiance arriving through the pixel (We cos / (p_pos p_dir) = 1).
    """
    scene, channels = settings.scene, settings.colours.channels
    camera = scene.camera
    count = pixels.size
    u = CAMERA_START.split(sampler.draw(CAMERA_START.size))
    origin, direction = camera.generate_rays(pixels, u.pixel, u.lens)
    origin = np.ascontiguousarray(origin, dtype=np.float32)
    axis = np.repeat(camera.forward.astype(np.float32)[:, None], count, axis=1)
    recorder = _Recorder(densities=settings.densities)
    record = recorder.add(np.arange(count), 0, CAMERA, p=origin, n=axis, beta=np.ones((channels, count)),
                          fwd=np.full(count, 1.0 / camera.lens_area), u=np.zeros((CAMERA_VERTEX.sizes["connect"], count)))
    lanes = _walk_lanes(count, settings.densities, origin=origin, direction=direction, beta=np.ones((channels, count)),
                        pdf=camera.pdf_direction(direction, origin), prev_n=axis, prev_infinite=np.zeros(count, bool))
    walk = Walk(scene, lanes, sampler, settings.camera_roulette, CAMERA_VERTEX)
    growth = _Growth(settings, walk, settings.light_roulette, recorder, record, count)
    growth.escapes = scene.lights.environment is not None
    if growth.escapes and not settings.densities:
        raise ValueError("camera_subpaths: vertices at infinity are recorded with their densities; walks without "
                         "densities cannot record them")
    growth.limit = limit
    growth.run()
    settings.counters.rays += growth.walk.rays
    return recorder.flatten(count, growth.terminated, settings.densities)


def light_subpaths(settings: SubpathSettings, count: int, sampler, lens: bool,
                   limit: np.ndarray | None = None) -> tuple[Subpaths, LensHits]:
    """``count`` light subpaths, one per lane, from ``sampler``'s numbers: (subpaths, lens hits); ``limit``:
    the most vertices of each lane's subpath (besides ``settings.max_vertices``; vertex 0 is always made).

    Vertex 0 is on a light chosen by power, with the origin density of
    :meth:`pathspace.lights.LightSet.pdf_le` and throughput 1 / (pmf x
    positional density) -- what a connection from it to the camera needs;
    the ray leaving it carries Le |cos| / (pmf p_pos p_dir).  ``lens``: look
    for rays through a thin lens.
    """
    recorder = _Recorder(densities=settings.densities)
    growth = _light_walk(settings, count, sampler, recorder, lens, limit)
    subpaths = recorder.flatten(count, growth.terminated, settings.densities)
    return subpaths, LensHits.concatenate(growth.lens_hits or [], settings.colours.channels)


def stream_light_vertices(settings: SubpathSettings, count: int, sampler, consume: Callable[[Subpaths], None],
                          chunk: int = STREAM_CHUNK) -> np.ndarray:
    """The light subpaths of :func:`light_subpaths` (the same numbers, the same vertices), handed to ``consume``
    while they are walked instead of kept (a light tracer joins them to the camera there, and keeps no
    vertices): first the vertices 0, one per lane in lane order, then the later
    vertices depth after depth, in calls of at least ``chunk`` vertices (the last one excepted) so that the
    few vertices of a long walk's last depths do not cost a call each.  Each call gets a :class:`Subpaths`
    without densities (walks that keep densities cannot stream, since their reverse densities are known only
    one vertex later), and but for the vertices 0 without ``offset`` (its vertices are not grouped by lane).  Returns ``terminated``
    (count,): the lanes whose walks kept only the hero wavelength somewhere."""
    if settings.densities:
        raise ValueError("stream_light_vertices: walks that keep densities cannot stream their vertices")
    names = [name for name in FIELDS if name not in DENSITY_FIELDS]
    pending: list[dict[str, np.ndarray]] = []
    started = False   # whether the vertices 0 went out

    def hand_over(offset: np.ndarray | None = None) -> None:
        if len(pending) == 1:
            fields = {name: pending[0][name] for name in names}
        else:
            fields = {name: np.concatenate([record[name] for record in pending], axis=-1) for name in names}
        pending.clear()
        consume(Subpaths(offset=offset, terminated=None, **{**dict.fromkeys(FIELDS), **fields}))

    def collect(record: dict[str, np.ndarray]) -> None:
        nonlocal started
        pending.append(record)
        if not started:   # the vertices 0 go alone: each lane's first vertex
            started = True
            hand_over(np.arange(count + 1, dtype=np.int64))
        elif sum(part["lane"].size for part in pending) >= chunk:
            hand_over()

    terminated = _light_walk(settings, count, sampler, _Recorder(collect, densities=False), False, None).terminated
    if pending:
        hand_over()
    return terminated


def _light_walk(settings: SubpathSettings, count: int, sampler, recorder: _Recorder, lens: bool,
                limit: np.ndarray | None) -> _Growth:
    """Walk ``count`` light subpaths (see :func:`light_subpaths`), recording their vertices in ``recorder``."""
    scene, colours = settings.scene, settings.colours
    lights = scene.lights
    u = LIGHT_START.split(sampler.draw(LIGHT_START.size))
    e = lights.sample_le(u.emission, colours, LIGHT_SELECTION)
    with np.errstate(divide="ignore", invalid="ignore"):
        beta0 = np.where(e.pdf_pos > 0, 1.0 / e.pdf_pos, 0.0)
        beta = e.value * np.where(e.pdf_dir > 0, beta0 * e.cos_light / e.pdf_dir, 0.0)
    origin_density = {"fwd": lights.pdf_le(e.entity, e.normal, e.direction)[0]} if settings.densities else {}
    record = recorder.add(np.arange(count), 0, LIGHT, p=e.point.astype(np.float32), n=e.normal, eps=e.epsilon,
                          beta=np.repeat(beta0[None, :], colours.channels, axis=0), entity=e.entity.astype(np.int64),
                          infinite=e.infinite, u=u.connect, **origin_density)
    # From a light at infinity the next vertex's density is the disk density, projected at the hit.
    pmf = lights.pmf("power").take(e.entity)
    with np.errstate(divide="ignore", invalid="ignore"):
        pdf = np.where(e.infinite, e.pdf_pos / pmf, e.pdf_dir)
    extra = {}
    if settings.light_roulette.policy == "throughput":  # the throughput is measured relative to the light's ray
        start = beta.max(axis=0)
        extra["rr_scale"] = np.divide(1.0, start, out=np.zeros_like(start), where=start > 0)
    origin = offset_origin(e.point.astype(np.float32), e.normal, e.epsilon, e.direction)
    lanes = _walk_lanes(count, settings.densities, origin=origin, direction=e.direction, beta=beta, pdf=pdf,
                        prev_n=e.normal, prev_infinite=e.infinite, **extra)
    walk = Walk(scene, lanes, sampler, settings.light_roulette, LIGHT_VERTEX, "importance")
    growth = _Growth(settings, walk, settings.camera_roulette, recorder, record, count)
    if lens and not settings.densities:
        raise ValueError("light_subpaths: rays through a thin lens are recorded with their densities; walks without "
                         "densities cannot record them")
    growth.lens_hits = [] if lens else None
    growth.limit = limit
    growth.run()
    settings.counters.rays += growth.walk.rays
    return growth
