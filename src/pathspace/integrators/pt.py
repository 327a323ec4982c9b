"""Path tracing (Kajiya 1986) over wavefronts, with every classic sampling strategy as a parameter.

Parameters
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
    produce the path);  "none": BSDF sampling alone (lights
    are found by chance; point, spot and directional lights are never found);
    "mixture": one direction per vertex from the mixture density
    alpha p_light + (1 - alpha) p_bsdf, weighted by the full mixture density
    (no shadow rays; the light density of a direction sums over every
    emitting surface along it).
mis : "power" (default), "balance" or "uniform"
    The MIS heuristic of "mis" (Veach 1997, eq. 9.13); "uniform" weighs both
    strategies 1/2 where both can produce the path.
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
rr, rr_depth, rr_probability, rr_cap
    Russian roulette policy and its parameters (see :mod:`pathspace.roulette`);
    default: throughput-based survival (pbrt-v4's rule) from depth 5.  The
    albedo it uses is the BSDF sample's weight, also under mixture sampling
    (whose weight f / p_mix is tiny toward bright lights, the directions that
    matter most).

Every wavefront lane carries one path.  Each bounce is a handful of array
operations over the live lanes, grouped by material kind, followed by
compaction; rays go to Embree in one batch per bounce (closest hits) plus one
batch of shadow rays.  New work items join the wavefront as paths end, so it
never dwindles to a tail of nearly empty bounces.  Each path consumes 4
random numbers for the camera (pixel position, lens) and 7 per bounce (light
choice and position, BSDF lobe and direction, roulette), plus one for the
mixture choice when mixture sampling, drawn whether used or not, so a
replaying sampler sees the same dimensions in the same order.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

from ..bsdfs import DIFFUSE_SAMPLING, MaterialLanes, Surface
from ..lights import MEASURES, SELECTIONS
from ..mis import HEURISTICS, mis_weight
from ..roulette import RussianRoulette
from ..sampler import StreamSampler
from ..vecmath import dot, leave_distance
from .base import TILE_PIXELS, WorkItem
from .visibility import light_sample_blocked
from .wavefront import ItemBook, Lanes

__all__ = ["PathTracer"]

LIGHT_SAMPLING = ("mis", "nee", "none", "mixture")
CAMERA_DIMS = 4
DIMS_PER_BOUNCE = 7  # + 1 for the mixture choice
# Paths still alive after this many segments are cut and counted (``truncated`` in the stats): only
# scenes that trap light without loss (mirror or glass enclosures) get there.
SAFETY_DEPTH = 10_000
# New work items join the wavefront while fewer paths than this are alive.
REFILL = TILE_PIXELS // 8


@dataclass
class PathTracer:
    """Unidirectional path tracer; see the module docstring for the parameters."""

    max_depth: int = -1
    light_sampling: str = "mis"
    mis: str = "power"
    mis_beta: float = 2.0
    mixture_alpha: float = 0.5
    diffuse_sampling: str = "cosine"
    light_selection: str = "power"
    light_measure: str = "area"
    rr: str = "throughput"
    rr_depth: int = 5
    rr_probability: float = 0.5
    rr_cap: float = 1.0
    roulette: RussianRoulette = field(init=False, repr=False)

    name = "pt"
    tile_pixels = TILE_PIXELS

    def __post_init__(self) -> None:
        if not (isinstance(self.max_depth, (int, np.integer)) and (self.max_depth == -1 or self.max_depth >= 1)):
            raise ValueError(f"max_depth: expected -1 (unbounded) or an integer >= 1, got {self.max_depth!r}")
        for name, choices in (("light_sampling", LIGHT_SAMPLING), ("mis", HEURISTICS),
                              ("diffuse_sampling", DIFFUSE_SAMPLING), ("light_selection", SELECTIONS),
                              ("light_measure", MEASURES)):
            if getattr(self, name) not in choices:
                raise ValueError(f"{name}: expected one of {choices}, got {getattr(self, name)!r}")
        if not (isinstance(self.mis_beta, (int, float)) and np.isfinite(self.mis_beta) and self.mis_beta > 0):
            raise ValueError(f"mis_beta: expected a finite number > 0, got {self.mis_beta!r}")
        if not (isinstance(self.mixture_alpha, (int, float)) and 0.0 <= self.mixture_alpha < 1.0):
            raise ValueError(f"mixture_alpha: expected a number in [0, 1), got {self.mixture_alpha!r}")
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
        delta = scene.materials.delta_names
        lines.append(f"specular (delta) materials: {', '.join(delta)}: no light sampling at their vertices"
                     if delta else "no specular (delta) materials: no specular code runs")
        return lines

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

    # -- rendering ---------------------------------------------------------------------------------

    def render_stream(self, scene, next_item, seed: int, mode, counters: dict) -> Iterator[tuple[WorkItem, np.ndarray]]:
        """Render work items taken from ``next_item()`` (None when there are no more) on one wavefront.

        Yields (item, values (3, n), None, None) as items finish:
        ``values[:, k]`` is the sample of pixel ``item.pixels[k]``, in RGB or
        XYZ as the colour ``mode`` says (the Nones: no splats, no
        per-strategy images; see :mod:`pathspace.integrators.bidirectional`).  New items join whenever fewer than ``REFILL`` paths
        are alive.  Adds ray and truncation counts to ``counters``.
        """
        lights = scene.lights
        options = {"diffuse_sampling": self.diffuse_sampling}
        strategy = self.light_sampling if lights.count else "none"
        env = lights.environment is not None
        book = ItemBook(3)
        sampler = StreamSampler(seed)
        fields = PATH_FIELDS + mode.path_fields
        paths = None
        exhausted = False
        while True:
            while not exhausted and (paths is None or paths.size < REFILL):
                item = next_item()
                if item is None:
                    exhausted = True
                    break
                tickets = book.open(item)
                u = sampler.add(item.keys, item.counts, CAMERA_DIMS + mode.camera_dims)
                origin, direction = scene.camera.generate_rays(item.pixels, u[0:2], u[2:4])
                new = Lanes(fields, **_new_paths(mode.channels, tickets, np.asarray(origin), direction),
                            **mode.start(u[CAMERA_DIMS:]))
                if paths is None:
                    paths = new
                else:
                    paths.extend(new)
            if paths is None or not paths.size:
                break
            counters["rays"] += self._bounce(scene, paths, sampler, book, strategy, env, mode, options, counters)
            for item, values in book.finished():
                yield item, values, None, None

    def _bounce(self, scene, paths, sampler, book, strategy, env, mode, options, counters) -> int:
        """Advance every path by one segment: trace, gather emission, sample lights and the BSDF, roulette."""
        mesh, lights, table = scene.mesh, scene.lights, scene.materials
        colours = mode.colours(paths)
        paths.depth += 1
        counters["longest"] = max(counters["longest"], int(paths.depth[0]))  # the oldest lane comes first
        hits = scene.accel.intersect(paths.origin, paths.direction, paths.tmin, normals=False, threads=1)
        rays = paths.size
        hit = hits.prim >= 0
        if env and not hit.all():
            self._escape(scene, ~hit, paths, strategy, colours)
        prim, b1, b2 = hits.prim, hits.u, hits.v
        # Paths end here if they escaped, reached max_depth (after counting emission) or the safety depth.
        end = ~hit
        if not hit.all():
            alive = np.flatnonzero(hit)
            _retire(book, paths, end, mode)
            paths.keep(alive, stale=("tmin",))  # every surviving path gets a new ray below
            sampler.keep(alive)
            prim, b1, b2 = prim.take(alive), b1.take(alive), b2.take(alive)
            if not paths.size:
                return rays
            colours = mode.colours(paths)
        p, normal, eps = mesh.hit_geometry(prim, b1, b2)
        cos_o = -dot(normal, paths.direction)
        if lights.area.count:
            self._emission(scene, prim, p, cos_o, paths, strategy, colours)
        stop = paths.depth >= (self.max_depth if self.max_depth > 0 else SAFETY_DEPTH)
        if stop.any():
            counters["truncated"] += int(np.count_nonzero(stop & (paths.depth >= SAFETY_DEPTH)))
            alive = np.flatnonzero(~stop)
            _retire(book, paths, stop, mode)
            paths.keep(alive, stale=("tmin",))
            sampler.keep(alive)
            prim, p, normal, eps, cos_o = (prim.take(alive), np.take(p, alive, axis=1),
                                           np.take(normal, alive, axis=1), eps.take(alive), cos_o.take(alive))
            if not paths.size:
                return rays
            colours = mode.colours(paths)
        surface = Surface.facing(normal, paths.direction, cos_o)

        u = sampler.draw(DIMS_PER_BOUNCE + (strategy == "mixture"))
        materials = MaterialLanes(table, mesh.material.take(prim), colours, options)
        if strategy in ("mis", "nee"):
            paths.radiance += self._next_event(scene, materials, p, surface, paths.beta, u[0:3], eps, colours)
            rays += paths.size

        sample = materials.sample(surface, u[3:6])
        # Roulette looks at the BSDF sample's weight (an albedo estimate): a mixture weight f / p_mix is
        # tiny exactly where a bright light about to be hit makes up for it, and would end such paths.
        albedo = sample.weight
        if strategy == "mixture":
            self._mixture(scene, materials, p, eps, surface, sample, u, colours)
        weight = sample.weight
        rr_throughput = paths.beta * albedo
        paths.beta = paths.beta * weight
        paths.pdf_prev, paths.delta_prev, paths.direction = sample.pdf, sample.delta, sample.wi
        if sample.terminated is not None:
            mode.terminate_secondary(paths, sample.terminated)
        paths.origin = p
        paths.tmin = leave_distance(eps, dot(surface.n, sample.wi))

        survival = self.roulette.survival(paths.depth, rr_throughput, albedo)
        keep = np.maximum(np.maximum(weight[0], weight[1]), weight[2]) > 0
        if survival is not None:
            keep &= u[6] < survival
            np.divide(paths.beta, survival, out=paths.beta, where=survival > 0)
        if not keep.all():
            live = np.flatnonzero(keep)
            _retire(book, paths, ~keep, mode)
            paths.keep(live)
            sampler.keep(live)
        return rays

    def _weight_of_hits(self, pdf_bsdf, pdf_light, delta_prev, strategy):
        """Weight of emission found by the current rays: MIS against light sampling, 1 where light
        sampling could not have produced it (camera rays, delta lobes), 0 for "nee" past those."""
        if strategy in ("none", "mixture"):
            return 1.0
        if strategy == "nee":
            return delta_prev.astype(np.float64)
        return np.where(delta_prev, 1.0, mis_weight(pdf_bsdf, pdf_light, self.mis, self.mis_beta))

    def _emission(self, scene, prim, p, cos_o, paths, strategy, colours):
        """Add emission of area lights hit by the current rays (Veach 1997, eq. 9.4 with 9.13)."""
        lights = scene.lights
        emitter = lights.area.emitter_of_triangle.take(prim)
        emits = np.flatnonzero(emitter >= 0)
        if not emits.size:
            return
        le = lights.area.emitted(emitter.take(emits), cos_o.take(emits), colours.take(emits))
        if strategy == "mis":
            pdf_light = lights.pdf_hit(prim.take(emits), np.take(paths.origin, emits, axis=1),
                                       np.take(p, emits, axis=1), self.light_selection, self.light_measure)
        else:
            pdf_light = None
        le = le * self._weight_of_hits(paths.pdf_prev.take(emits), pdf_light, paths.delta_prev.take(emits), strategy)
        paths.radiance[:, emits] += np.take(paths.beta, emits, axis=1) * le

    def _escape(self, scene, escaped, paths, strategy, colours):
        """Add environment radiance to rays that left the scene."""
        lanes = np.flatnonzero(escaped)
        env = scene.lights.environment_radiance(lanes.size, colours.take(lanes))
        pdf_env = np.full(lanes.size, scene.lights.pdf_environment(self.light_selection))
        env = env * self._weight_of_hits(paths.pdf_prev.take(lanes), pdf_env, paths.delta_prev.take(lanes), strategy)
        paths.radiance[:, lanes] += np.take(paths.beta, lanes, axis=1) * env

    def _next_event(self, scene, materials, p, surface, beta, u, eps, colours) -> np.ndarray:
        """Light-sampled direct illumination of every lane, MIS-weighted against BSDF sampling; (C, N).

        Estimates Le f |cos| / p_light (Veach 1997, eq. 9.4) with one light
        sample and one shadow ray per lane where the contribution is non-zero.
        Delta materials get nothing (f is zero for any light direction).
        """
        ls = scene.lights.sample(p, u, colours, self.light_selection, self.light_measure)
        f_cos, pdf_bsdf = materials.eval(surface, ls.wi)
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = 1.0 / ls.pdf
        if self.light_sampling == "mis":
            w = mis_weight(ls.pdf, pdf_bsdf, self.mis, self.mis_beta)
            scale *= np.where(ls.delta, 1.0, w) if scene.lights.has_delta else w
        useful = ls.facing & (scale > 0) & (np.maximum(np.maximum(f_cos[0], f_cos[1]), f_cos[2]) > 0)
        lanes = np.flatnonzero(useful)
        if lanes.size:
            useful[lanes[light_sample_blocked(scene, p, eps, surface.n, ls, lanes)]] = False
        return np.where(useful, beta * f_cos * (ls.value * scale), 0.0)

    # -- mixture sampling --------------------------------------------------------------------------

    def _mixture(self, scene, materials, p, eps, surface, sample, u, colours) -> None:
        """Turn BSDF samples into samples of the mixture alpha p_light + (1 - alpha) p_bsdf (in place).

        With probability alpha a lane takes the direction of a light sample
        instead; either way its weight becomes f |cos| / p_mix and its pdf
        p_mix.  Delta lobes keep their BSDF sample: no light sample can match them.
        """
        ls = scene.lights.sample(p, u[0:3], colours, self.light_selection, self.light_measure)
        use_light = u[7] < self.mixture_alpha
        if materials.delta is not None:
            use_light &= ~materials.delta
        wi = np.where(use_light, ls.wi, sample.wi)
        f_cos, pdf_bsdf = materials.eval(surface, wi)
        pdf_light = self._light_density(scene, p, leave_distance(eps, dot(surface.n, wi)), wi)
        alpha = self.mixture_alpha
        pdf = alpha * pdf_light + (1.0 - alpha) * pdf_bsdf
        with np.errstate(divide="ignore", invalid="ignore"):
            weight = np.where(pdf > 0, f_cos / pdf, 0.0)
        delta = sample.delta
        sample.wi = wi
        sample.weight = np.where(delta, sample.weight, weight)
        sample.pdf = np.where(delta, sample.pdf, pdf)

    def _light_density(self, scene, receivers, tmin, direction):
        """Solid-angle density with which light sampling at ``receivers`` produces each direction.

        Sums over every emitting triangle the ray meets (found with an
        emitter-only BVH, hit after hit) and the environment.
        """
        lights = scene.lights
        count = direction.shape[1]
        total = np.full(count, lights.pdf_environment(self.light_selection))
        if not lights.area.count:
            return total
        emitters = scene.emitter_accel
        lanes = np.arange(count)
        o, d = receivers, direction
        while lanes.size:
            h = emitters.intersect(o, d, tmin, np.inf, normals=False, threads=1)
            found = np.flatnonzero(h.prim >= 0)
            lanes, o, d = lanes.take(found), np.take(o, found, axis=1), np.take(d, found, axis=1)
            prim, t = h.prim.take(found), h.t.take(found)
            tri = lights.area.triangles.take(prim)
            points = o + d * t
            total[lanes] += lights.pdf_hit(tri, np.take(receivers, lanes, axis=1), points, self.light_selection,
                                           self.light_measure)
            tmin = t * np.float32(1 + 1e-5) + np.float32(1e-30)
        return total


PATH_FIELDS = ("ticket", "depth", "origin", "direction", "tmin", "beta", "radiance", "pdf_prev", "delta_prev")


def _new_paths(channels: int, tickets: np.ndarray, origin: np.ndarray, direction: np.ndarray):
    """State of camera paths about to trace their first segment (``tickets``: see :class:`ItemBook`)."""
    n = tickets.size
    return dict(ticket=tickets, depth=np.zeros(n, dtype=np.int32),
                origin=np.ascontiguousarray(origin, dtype=np.float32), direction=direction,
                tmin=np.zeros(n, dtype=np.float32),  # where the ray starts (see leave_distance)
                beta=np.ones((channels, n)),                              # path throughput
                radiance=np.zeros((channels, n)),                         # radiance gathered so far
                pdf_prev=np.zeros(n),                    # solid-angle pdf of the sampled direction of the current ray
                delta_prev=np.ones(n, dtype=bool))       # the previous vertex was the camera or a delta lobe


def _retire(book: ItemBook, paths: Lanes, done: np.ndarray, mode) -> None:
    """Hand the radiance of the paths that end here (``done``), as film values, to their items."""
    lanes = np.flatnonzero(done)
    if lanes.size:
        book.store(paths.ticket.take(lanes), mode.to_film(np.take(paths.radiance, lanes, axis=1), paths, lanes))
