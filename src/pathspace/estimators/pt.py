"""Path tracing (Kajiya 1986) over wavefronts, with every classic sampling strategy as a parameter.

Parameters (``PathTracer.parameters()`` lists them with their meaning)
----------
max_depth : int, default -1
    Longest path in segments; -1 is unbounded (the full solution).  1 shows
    only emitters seen directly, 2 adds direct illumination.
light_sampling : "mis" (default), "nee", "none" or "mixture"
    How emitters are reached past the first segment:
    "mis": next-event estimation (one light sample and shadow ray per vertex)
    and BSDF sampling, combined by multiple importance sampling (Veach 1997,
    ch. 9);  "nee": next-event estimation alone (emitters hit by BSDF samples
    count only after the camera and delta lobes, where light sampling cannot
    produce the path);  "none": BSDF sampling alone (lights are found by
    chance; point, spot and directional lights are never found);
    "mixture": one direction per vertex from the mixture density
    alpha p_light + (1 - alpha) p_bsdf, weighted by the full mixture density
    (no shadow rays; the light density of a direction sums over every
    emitting surface along it).
mis : "power" (default), "balance" or "uniform"
    The MIS heuristic of "mis" (Veach 1997, eq. 9.13; see :mod:`pathspace.mis`);
    "uniform" weighs both strategies 1/2 where both can produce the path.
mis_beta : float, default 2
    Exponent of the power heuristic.
mixture_alpha : float in [0, 1), default 0.5
    Probability of sampling a light direction in "mixture" (1 is refused: it
    would never sample the directions no light lies in, i.e. indirect light).
diffuse_sampling : "cosine" (default) or "uniform"
    BSDF sampling technique of diffuse surfaces.
light_selection : "power" (default) or "uniform"
    How a light is chosen for a light sample (see :mod:`pathspace.lights`).
light_measure : "area" (default) or "solid_angle"
    How a point on an emitting triangle is sampled.
kernel : "fused" (default) or "numpy"
    Where a vertex's work is done.  "fused": next-event estimation, BSDF
    sampling and roulette in one C pass per bounce for the scenes it serves
    (RGB; diffuse, mirror and smooth dielectric materials; light samples on
    area lights by area; see :mod:`pathspace.estimators.pt_fused`), the
    NumPy code elsewhere; "numpy": always the NumPy code, the reference the
    fused kernel is tested against.  Both give the same image bit for bit.
rr, rr_depth, rr_probability, rr_cap
    Russian roulette (see :mod:`pathspace.roulette`); default: throughput-based
    survival (pbrt-v4's rule) from depth 5.  The throughput it reads includes
    the BSDF sample's weight, also under mixture sampling (whose weight
    f / p_mix is tiny toward bright lights, the directions that matter most).

Every wavefront lane carries one path (a :class:`~pathspace.estimators.walk.Walk`).
Each bounce is a handful of array operations over the live lanes, grouped by
material kind, followed by compaction; rays go to Embree in one batch per
bounce (closest hits) plus one batch of shadow rays.  New work items join
the wavefront as paths end, so it never dwindles to a tail of nearly empty
bounces.  The numbers each path draws are :meth:`PathTracer.dimensions`:
the camera's, then per vertex the light sample's, the BSDF sample's, the
roulette's and (mixture sampling) the mixture choice's, drawn whether used or
not, so that a replaying sampler sees the same dimensions in the same order.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Iterator

import numpy as np

from .. import _native
from ..bsdfs import MaterialLanes
from ..checks import choice, number
from ..mis import TWO_STRATEGY, mis_weight
from ..roulette import RussianRoulette, roulette_warnings
from ..sampler import Sampler
from ..spectra import RGBMode
from ..vecmath import RAY_TMIN, dot, offset_origin
from . import parameters as p
from .base import TILE_PIXELS, Counters, Estimator, ItemResult, RenderJob, WorkItem, parameter
from .pt_fused import FusedVertex, fused_vertex
from .visibility import light_sample_blocked
from .walk import WALK_FIELDS, Arrival, Dimensions, Walk
from .wavefront import ItemBook, Lanes

__all__ = ["PathTracer"]

LIGHT_SAMPLING = ("mis", "nee", "none", "mixture")
CAMERA_DIMENSIONS = Dimensions(pixel=2, lens=2)
# Paths still alive after this many segments are cut and counted (``truncated`` in the stats): only
# scenes that trap light without loss (mirror or glass enclosures) get there.
SAFETY_DEPTH = 10_000
# New work items join the wavefront while fewer paths than this are alive.
REFILL = TILE_PIXELS // 8
# Paths this deep (light trapped in glass by total internal reflection, mostly) leave the wavefront for a small
# one that takes DEEP_STEPS bounces per bounce of the large one: a long path must not hold its work item
# (and every item after it) for thousands of bounces of the whole wavefront.  Few steps let the deep paths of
# several items share each step (a step of a few lanes costs as much as one of thousands): on the specular
# box, 8-s renders reach ~25% more samples with 8 steps than with 32 or 256; with 1, items wait too long.
DEEP_DEPTH = 32
DEEP_STEPS = 8
PATH_FIELDS = WALK_FIELDS + ("ticket", "radiance")
# The strategies' weights as ext/direct.c numbers them: "none" unweighted, the MIS heuristics, and "nee" (emitters
# hit by BSDF samples where light samples are taken alone: 0 but after the camera and delta lobes).
MIS_CODES = {"none": 0, "balance": 1, "power": 2, "uniform": 3, "nee": 4}


@dataclass
class _Bounce:
    """What every bounce of one wavefront reads: the scene, the colour mode, the light strategy in use
    (none without lights), whether there is an environment, where finished paths go, the counters, and the
    fused vertex kernel if it serves the scene (see :mod:`pathspace.estimators.pt_fused`)."""

    scene: object
    mode: object
    strategy: str
    environment: bool
    book: ItemBook
    counters: Counters
    fused: FusedVertex | None = None


@dataclass
class PathTracer(Estimator):
    """Unidirectional path tracer; see the module docstring for the parameters."""

    max_depth: int = p.max_depth()
    light_sampling: str = parameter("mis", "how emitters are reached: 'mis' (next-event estimation + BSDF sampling), "
                                           "'nee', 'none' (BSDF sampling only), 'mixture'",
                                    lambda v, n: choice(v, n, LIGHT_SAMPLING))
    mis: str = p.mis_heuristic("power", TWO_STRATEGY)
    mis_beta: float = p.mis_beta()
    mixture_alpha: float = parameter(0.5, "with light_sampling='mixture': probability of sampling a light direction",
                                     lambda v, n: number(v, n, low=0.0, high=1.0, high_open=True))
    diffuse_sampling: str = p.diffuse_sampling()
    light_selection: str = p.light_selection()
    light_measure: str = p.light_measure()
    kernel: str = p.kernel("a vertex's work")
    rr: str = p.roulette_policy("throughput")
    rr_depth: int = p.roulette_depth(5)
    rr_probability: float = p.roulette_probability()
    rr_cap: float = p.roulette_cap()
    roulette: RussianRoulette = field(init=False, repr=False)

    name = "pt"

    def __post_init__(self) -> None:
        super().__post_init__()
        self.roulette = RussianRoulette(self.rr, self.rr_depth, self.rr_probability, self.rr_cap)

    # -- description -------------------------------------------------------------------------------

    def plan(self, scene) -> list[str]:
        """What this estimator will do on ``scene``, and what it leaves out and why."""
        depth = "unbounded" if self.max_depth < 0 else self.max_depth
        lines = [f"path tracing, max_depth={depth}; {self.roulette.describe()}",
                 f"diffuse surfaces sampled {self.diffuse_sampling}-weighted"]
        lights = scene.lights
        if lights.count == 0:
            lines.append("no lights in the scene: the image is black; light sampling skipped")
        elif self.light_sampling == "mis":
            heuristic = f"{self.mis} heuristic" + (f" (beta={self.mis_beta:g})" if self.mis == "power" else "")
            lines.append(f"next-event estimation + BSDF sampling, {heuristic}; lights chosen by "
                         f"{self.light_selection}, points sampled by {self.light_measure.replace('_', ' ')}")
        elif self.light_sampling == "mixture":
            lines.append(f"one direction per vertex from {self.mixture_alpha:g} p_light + "
                         f"{1 - self.mixture_alpha:g} p_bsdf; no shadow rays")
        else:
            lines.append({"nee": "next-event estimation only", "none": "BSDF sampling only"}[self.light_sampling])
        if lights.has_delta and self.light_sampling in ("mis", "nee"):
            lines.append("point/spot/directional lights: light sampling only (BSDF samples cannot hit them)")
        strategy = self._strategy(scene)
        fused, reason = fused_vertex(self, scene, RGBMode(), strategy, self._heuristic(strategy))
        lines.append("vertices in one C pass (the fused kernel) in RGB, in NumPy when spectral" if fused is not None
                     else f"vertices in NumPy ({reason})")
        delta = scene.materials.delta_names
        lines.append(f"specular (delta) materials: {', '.join(delta)}: no light sampling at their vertices"
                     if delta else "no specular (delta) materials: no specular code runs")
        return lines

    def warnings(self, scene) -> list[str]:
        """Roulette settings with infinite variance on ``scene``."""
        return roulette_warnings(self.roulette, scene.materials, self.max_depth)

    def check(self, scene) -> None:
        """Raise ValueError if this estimator cannot render ``scene`` correctly."""
        if self.light_sampling in ("none", "mixture") and scene.lights.has_delta:
            raise ValueError(f"light_sampling={self.light_sampling!r} cannot reach point, spot or directional "
                             "lights (no ray can hit them); use 'mis' or 'nee'")

    def prepare(self, scene) -> None:
        """Build the acceleration structures this estimator uses on ``scene``."""
        scene.accel
        if self.light_sampling == "mixture" and scene.lights.area.count:
            scene.emitter_accel

    def dimensions(self, mode) -> tuple[Dimensions, Dimensions]:
        """The numbers a path draws: (at the camera, at every vertex), in the order drawn."""
        vertex = Dimensions(light=3, bsdf=3, roulette=1)
        if self.light_sampling == "mixture":
            vertex = vertex + Dimensions(mixture=1)
        return CAMERA_DIMENSIONS + Dimensions(wavelengths=mode.camera_dims), vertex

    # -- rendering ---------------------------------------------------------------------------------

    def render_items(self, job: RenderJob, next_item: Callable[[], WorkItem | None],
                     counters: Counters) -> Iterator[ItemResult]:
        """Render work items on one persistent wavefront: new items join whenever fewer than ``REFILL``
        paths are alive, and an item is yielded as soon as its last path ends.  Refused an item (a time budget's
        deadline, see :mod:`~pathspace.estimators.passes`), the wavefront drains and asks once more: an item
        rendered alone ends sooner than one queued behind others, and may still fit."""
        bounce = self._bounce_context(job.scene, job.mode, counters)
        walk = deep = None
        exhausted = asked_drained = False
        while True:
            job.control.check()
            while not exhausted and (walk is None or walk.size < REFILL):
                item = next_item()
                if item is None:
                    exhausted = True
                    break
                asked_drained = False
                new = self._start(bounce, item.pixels, job.samplers.open(item.keys, item.counts),
                                  bounce.book.open(item, item.pixels.size))
                if walk is None:
                    walk = new
                else:
                    walk.extend(new)
            if walk is None or not (walk.size or (deep is not None and deep.size)):
                if walk is None or asked_drained:
                    break
                exhausted, asked_drained = False, True
                continue
            deep = self._advance(walk, deep, bounce)
            counters.rays += walk.rays + deep.rays
            walk.rays = deep.rays = 0
            for item, values in bounce.book.finished():
                yield ItemResult(item, values)

    def _advance(self, walk: Walk, deep: Walk | None, bounce: "_Bounce") -> Walk:
        """One bounce of the wavefront, then up to DEEP_STEPS bounces of its deep paths; returns the deep walk."""
        if walk.size:
            self._bounce(walk, bounce)
        going = np.flatnonzero(walk.lanes.depth >= DEEP_DEPTH)
        if deep is None:
            deep = walk.split(going)
        elif going.size:
            deep.extend(walk.split(going))
        for _ in range(DEEP_STEPS):
            if not deep.size:
                break
            self._bounce(deep, bounce)
        return deep

    def evaluate(self, scene, pixels: np.ndarray, sampler: Sampler, mode=None,
                 counters: Counters | None = None) -> np.ndarray:
        """Film values (3, N) of the paths through ``pixels`` (N,) built from ``sampler``'s numbers (a
        sampler of N lanes, e.g. a :class:`~pathspace.sampler.ReplaySampler` of primary samples drawn in
        the order of :meth:`dimensions`): the samples a render would add for these numbers.  Rays and
        path lengths are counted into ``counters`` if given."""
        mode = RGBMode() if mode is None else mode
        self.check(scene)
        counters = Counters() if counters is None else counters
        bounce = self._bounce_context(scene, mode, counters)
        walk = self._start(bounce, np.asarray(pixels, dtype=np.int64), sampler, bounce.book.open("paths", len(pixels)))
        deep = None
        while walk.size or deep.size:
            deep = self._advance(walk, deep, bounce)
            counters.rays += walk.rays + deep.rays
            walk.rays = deep.rays = 0
        return bounce.book.finished()[0][1]

    def _strategy(self, scene) -> str:
        """The light strategy in use on ``scene``: none without lights."""
        return self.light_sampling if scene.lights.count else "none"

    def _heuristic(self, strategy: str) -> int:
        """How light samples are weighted (``MIS_CODES``), -1 if none are taken."""
        return {"mis": MIS_CODES[self.mis], "nee": MIS_CODES["none"]}.get(strategy, -1)

    def _bounce_context(self, scene, mode, counters: Counters) -> _Bounce:
        strategy = self._strategy(scene)
        return _Bounce(scene, mode, strategy, scene.lights.environment is not None, ItemBook(3), counters,
                       fused_vertex(self, scene, mode, strategy, self._heuristic(strategy))[0])

    def _start(self, bounce: _Bounce, pixels: np.ndarray, sampler: Sampler, tickets: np.ndarray) -> Walk:
        """Camera paths through ``pixels`` about to trace their first segment."""
        mode = bounce.mode
        camera_dims, vertex_dims = self.dimensions(mode)
        u = camera_dims.split(sampler.draw(camera_dims.size))
        origin, direction = bounce.scene.camera.generate_rays(pixels, u.pixel, u.lens)
        n = pixels.size
        lanes = Lanes(PATH_FIELDS + mode.path_fields, ticket=tickets, depth=np.zeros(n, dtype=np.int32),
                      origin=np.ascontiguousarray(origin, dtype=np.float32), direction=direction,
                      beta=np.ones((mode.channels, n)),
                      radiance=np.zeros((mode.channels, n)),
                      pdf=np.zeros(n), delta=np.ones(n, dtype=bool),  # the camera: no light sample could
                      **mode.start(u.wavelengths))                    # have produced what its rays find
        return Walk(bounce.scene, lanes, sampler, self.roulette, vertex_dims)

    def _bounce(self, walk: Walk, bounce: _Bounce) -> None:
        """Advance every path by one segment: trace, gather emission, sample lights and the BSDF, roulette."""
        scene, lanes = bounce.scene, walk.lanes
        hits = walk.trace()
        bounce.counters.longest = max(bounce.counters.longest, int(lanes.depth[0]))  # the oldest lane comes first
        hit = hits.prim >= 0
        if bounce.environment and not hit.all():
            self._escape(scene, np.flatnonzero(~hit), lanes, bounce)
        # Paths end here if they escaped, reached max_depth (after counting emission) or the safety depth.
        prim, b1, b2, t = hits.prim, hits.u, hits.v, hits.t
        if not hit.all():
            alive = np.flatnonzero(hit)
            self._retire(bounce, lanes, ~hit)
            prim, b1, b2, t = walk.keep(alive, prim, b1, b2, t)
            if not walk.size:
                return
        arrival = walk.arrive(prim, b1, b2, t)
        if scene.lights.area.count:
            self._emission(scene, arrival, lanes, bounce)
        stop = lanes.depth >= (self.max_depth if self.max_depth > 0 else SAFETY_DEPTH)
        if stop.any():
            bounce.counters.truncated += int(np.count_nonzero(stop & (lanes.depth >= SAFETY_DEPTH)))
            self._retire(bounce, lanes, stop)
            alive = np.flatnonzero(~stop)
            walk.keep(alive)
            arrival = arrival.keep(alive)
            if not walk.size:
                return
        self._scatter(walk, arrival, bounce)

    def _scatter(self, walk: Walk, arrival: Arrival, bounce: _Bounce) -> None:
        """Next-event estimation and the next direction at every lane's vertex."""
        if bounce.fused is not None:
            self._fused_scatter(walk, arrival, bounce)
            return
        scene, lanes, mode = bounce.scene, walk.lanes, bounce.mode
        colours = mode.colours(lanes)
        u = walk.draw()
        materials = MaterialLanes(scene.materials, arrival.material, colours, {"diffuse_sampling": self.diffuse_sampling})
        if bounce.strategy in ("mis", "nee"):
            self._light_samples(walk, materials, arrival, u.light, colours, bounce)
        sample = materials.sample(arrival.surface, u.bsdf)
        # Roulette reads the BSDF sample's weight (an albedo estimate): a mixture weight f / p_mix is
        # tiny exactly where a bright light about to be hit makes up for it, and would end such paths.
        survival = walk.survival(arrival, sample)
        if bounce.strategy == "mixture":
            self._mixture(scene, materials, arrival, sample, u, colours)
        if sample.terminated is not None:
            mode.terminate_secondary(lanes, sample.terminated)
        alive = walk.scatter(arrival, sample, u.roulette, survival)
        if not alive.all():
            self._retire(bounce, lanes, ~alive)
            walk.keep(np.flatnonzero(alive))

    def _fused_scatter(self, walk: Walk, arrival: Arrival, bounce: _Bounce) -> None:
        """:meth:`_scatter` in one C pass (``ext/pt_vertex.c``) but for the shadow rays, bit for bit."""
        lanes = walk.lanes
        out = bounce.fused(arrival, lanes, walk.numbers())
        walk.rays += out.light_samples
        useful = np.flatnonzero(out.useful)
        if useful.size:
            blocked = bounce.scene.accel.occluded_between(arrival.p, out.normal, arrival.eps, out.light_point,
                                                          out.light_normal, out.light_eps, useful, threads=1)
            out.value[:, useful[blocked]] = 0.0
        lanes.radiance += out.value
        lanes.beta, lanes.origin, lanes.direction, lanes.pdf, lanes.delta = (out.beta, out.origin, out.direction,
                                                                             out.pdf, out.delta)
        if out.eta_scale is not None:
            lanes.eta_scale = out.eta_scale
        if not out.alive.all():
            self._retire(bounce, lanes, ~out.alive)
            walk.keep(np.flatnonzero(out.alive))

    @staticmethod
    def _retire(bounce: _Bounce, lanes: Lanes, done: np.ndarray) -> None:
        """Hand the radiance of the paths that end here (``done``), as film values, to their items."""
        idx = np.flatnonzero(done)
        if idx.size:
            bounce.book.store(lanes.ticket.take(idx),
                              bounce.mode.to_film(np.take(lanes.radiance, idx, axis=1), lanes, idx))

    # -- emission found by the walk -----------------------------------------------------------------

    def _weight_of_hits(self, pdf_bsdf, pdf_light, delta_prev, strategy):
        """Weight of emission found by the current rays: MIS against light sampling, 1 where light
        sampling could not have produced it (camera rays, delta lobes), 0 for "nee" past those."""
        if strategy in ("none", "mixture"):
            return 1.0
        if strategy == "nee":
            return delta_prev.astype(np.float64)
        return np.where(delta_prev, 1.0, mis_weight(pdf_bsdf, pdf_light, self.mis, self.mis_beta))

    def _emission(self, scene, arrival: Arrival, lanes: Lanes, bounce: _Bounce) -> None:
        """Add emission of area lights hit by the current rays (Veach 1997, eq. 9.4 with 9.13): which lanes hit
        one and the weights are one C pass (``ext/direct.c``), but for MIS against light samples by solid angle."""
        area = scene.lights.area   # area lights are the first entities: emitting triangle = entity
        if bounce.strategy == "mis" and self.light_measure != "area":
            emits, entity, weight = self._emitters_hit(scene, arrival, lanes, bounce)
        else:
            strategy = {"mis": self.mis, "nee": "nee"}.get(bounce.strategy, "none")
            geometry = (np.ascontiguousarray(a, np.float32) for a in (lanes.origin, arrival.p, arrival.normal,
                                                                      lanes.direction))
            emits, entity, weight = _native.area_emission(
                np.ascontiguousarray(arrival.prim, np.int32), area.emitter_of_triangle, area.table, area.area,
                area.two_sided, scene.lights.pmf(self.light_selection), *geometry,
                np.ascontiguousarray(lanes.pdf, np.float64), np.ascontiguousarray(lanes.delta, bool),
                MIS_CODES[strategy], self.mis_beta)
        if emits.size:
            le = area.radiance_of(entity, bounce.mode.colours(lanes).take(emits))
            lanes.radiance[:, emits] += np.take(lanes.beta, emits, axis=1) * (le * weight)

    def _emitters_hit(self, scene, arrival: Arrival, lanes: Lanes, bounce: _Bounce):
        """(lanes, emitting triangles, weights) of the current rays that hit an area light: what
        ``_native.area_emission`` finds, in NumPy, with the light-sampling densities of any measure."""
        lights = scene.lights
        entity = lights.area.emitter_of_triangle.take(arrival.prim)
        emits = np.flatnonzero(entity >= 0)
        entity = entity.take(emits)
        normal, wo = np.take(arrival.normal, emits, axis=1), -np.take(lanes.direction, emits, axis=1)
        facing = lights.area.faces(entity, dot(normal, wo))
        pdf_light = None
        if bounce.strategy == "mis":
            pdf_light = lights.pdf_li(entity, np.take(lanes.origin, emits, axis=1), np.take(arrival.p, emits, axis=1),
                                      self.light_selection, self.light_measure)
        weight = self._weight_of_hits(lanes.pdf.take(emits), pdf_light, lanes.delta.take(emits), bounce.strategy)
        return emits, entity, np.where(facing, weight, 0.0)

    def _escape(self, scene, escaped: np.ndarray, lanes: Lanes, bounce: _Bounce) -> None:
        """Add environment radiance to the rays ``escaped`` that left the scene."""
        lights = scene.lights
        entity = np.full(escaped.size, lights.environment_entity)
        d = np.take(lanes.direction, escaped, axis=1)
        env = lights.le(entity, d, -d, bounce.mode.colours(lanes).take(escaped))
        pdf_env = lights.pdf_li(entity, d, d, self.light_selection, self.light_measure)
        env = env * self._weight_of_hits(lanes.pdf.take(escaped), pdf_env, lanes.delta.take(escaped), bounce.strategy)
        lanes.radiance[:, escaped] += np.take(lanes.beta, escaped, axis=1) * env

    # -- light sampling ----------------------------------------------------------------------------

    def _light_samples(self, walk: Walk, materials, arrival: Arrival, u, colours, bounce: _Bounce) -> None:
        """Next-event estimation at the lanes whose material is not specular (which could use no light sample)."""
        lanes, scene = walk.lanes, bounce.scene
        if materials.delta is None:
            lanes.radiance += self._next_event(scene, materials, arrival, lanes.beta, u, colours)
            walk.rays += lanes.size
            return
        todo, subset = materials.part(specular=False)
        if todo.size:
            lanes.radiance[:, todo] += self._next_event(scene, subset, arrival.keep(todo),
                                                        np.take(lanes.beta, todo, axis=1), np.take(u, todo, axis=1),
                                                        colours.take(todo))
            walk.rays += todo.size

    def _next_event(self, scene, materials, arrival: Arrival, beta, u, colours) -> np.ndarray:
        """Light-sampled direct illumination of every lane, MIS-weighted against BSDF sampling; (C, N).

        Estimates Le f |cos| / p_light (Veach 1997, eq. 9.4) with one light
        sample and one shadow ray per lane where the contribution is non-zero.
        Delta materials get nothing (f is zero for any light direction).  The
        weighting is one C pass (``ext/direct.c``).
        """
        p, surface = arrival.p, arrival.surface
        ls = scene.lights.sample_li(p, u, colours, self.light_selection, self.light_measure)
        f_cos, pdf_bsdf = materials.eval(surface, ls.wi)
        heuristic = self._heuristic(self.light_sampling)
        weighed = (np.ascontiguousarray(a, np.float64) for a in (beta, f_cos, ls.value, ls.pdf, pdf_bsdf))
        delta = np.ascontiguousarray(ls.delta, bool) if scene.lights.has_delta else None
        value, useful = _native.next_event_value(*weighed, np.ascontiguousarray(ls.facing, bool), delta, heuristic,
                                                 self.mis_beta)
        lanes = np.flatnonzero(useful)
        if lanes.size:
            value[:, lanes[light_sample_blocked(scene, p, arrival.eps, surface.n, ls, lanes)]] = 0.0
        return value

    def _mixture(self, scene, materials, arrival: Arrival, sample, u, colours) -> None:
        """Turn BSDF samples into samples of the mixture alpha p_light + (1 - alpha) p_bsdf (in place).

        With probability alpha a lane takes the direction of a light sample
        instead; either way its weight becomes f |cos| / p_mix and its pdf
        p_mix.  Delta lobes keep their BSDF sample: no light sample can match them.
        """
        p, surface = arrival.p, arrival.surface
        ls = scene.lights.sample_li(p, u.light, colours, self.light_selection, self.light_measure)
        use_light = u.mixture[0] < self.mixture_alpha
        if materials.delta is not None:
            use_light &= ~materials.delta
        wi = np.where(use_light, ls.wi, sample.wi)
        f_cos, pdf_bsdf = materials.eval(surface, wi)
        pdf_light = self._light_density(scene, p, offset_origin(p, arrival.normal, arrival.eps, wi), wi)
        alpha = self.mixture_alpha
        pdf = alpha * pdf_light + (1.0 - alpha) * pdf_bsdf
        with np.errstate(divide="ignore", invalid="ignore"):
            weight = np.where(pdf > 0, f_cos / pdf, 0.0)
        delta = sample.delta
        sample.wi = wi
        sample.weight = np.where(delta, sample.weight, weight)
        sample.pdf = np.where(delta, sample.pdf, pdf)

    def _light_density(self, scene, receivers, origins, direction):
        """Solid-angle density with which light sampling at ``receivers`` produces each direction.

        Sums over every emitting triangle the ray from ``origins`` (the receivers, offset off their
        surface) meets -- found with an emitter-only BVH, hit after hit -- and the environment.
        """
        lights = scene.lights
        count = direction.shape[1]
        total = np.zeros(count)
        if lights.environment is not None:
            total += lights.pdf_li(np.full(count, lights.environment_entity), direction, direction,
                                   self.light_selection, self.light_measure)
        if not lights.area.count:
            return total
        emitters = scene.emitter_accel
        lanes = np.arange(count)
        o, d, tmin = origins, direction, RAY_TMIN
        while lanes.size:
            h = emitters.intersect(o, d, tmin, np.inf, normals=False, threads=1)
            found = np.flatnonzero(h.prim >= 0)
            lanes, o, d = lanes.take(found), np.take(o, found, axis=1), np.take(d, found, axis=1)
            entity, t = h.prim.take(found), h.t.take(found)  # emitter-BVH primitives are area-light entities
            points = o + d * t
            total[lanes] += lights.pdf_li(entity, np.take(receivers, lanes, axis=1), points, self.light_selection,
                                          self.light_measure)
            tmin = t * np.float32(1 + 1e-5) + np.float32(1e-30)
        return total
