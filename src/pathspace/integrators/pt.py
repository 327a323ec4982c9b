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
    are ignored past the first segment);  "none": BSDF sampling alone (lights
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
mixture_alpha : float in [0, 1], default 0.5
    Probability of sampling a light direction in "mixture".
diffuse_sampling : "cosine" (default) or "uniform"
    BSDF sampling technique of diffuse surfaces.
light_selection : "power" (default) or "uniform"
    How a light is chosen for a light sample (see :mod:`pathspace.lights`).
light_measure : "area" (default) or "solid_angle"
    How a point on an emitting triangle is sampled.
rr, rr_depth, rr_probability, rr_cap
    Russian roulette policy and its parameters (see :mod:`pathspace.roulette`);
    default: throughput-based survival (pbrt-v4's rule) from depth 5.

Every wavefront lane carries one path.  All live lanes are at the same depth,
so each bounce is a handful of array operations over the live lanes, grouped
by material kind, followed by compaction; rays go to Embree in one batch per
bounce (closest hits) plus one batch of shadow rays.  Each path consumes 4
random numbers for the camera (pixel position, lens) and 8 per bounce (light
choice and position, BSDF lobe and direction, roulette, mixture choice),
drawn whether used or not, so a replaying sampler sees the same dimensions in
the same order.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..bsdfs import DIFFUSE_SAMPLING, MaterialLanes
from ..colours import RGBColours
from ..lights import MEASURES, SELECTIONS
from ..mis import HEURISTICS, mis_weight
from ..roulette import RussianRoulette
from ..vecmath import dot, offset_along
from .base import ItemResult, WorkItem

__all__ = ["PathTracer"]

LIGHT_SAMPLING = ("mis", "nee", "none", "mixture")
CAMERA_DIMS = 4
DIMS_PER_BOUNCE = 8
# Paths still alive after this many segments are cut and counted (``truncated`` in the stats): only
# scenes that trap light without loss (mirror or glass enclosures) get there.
SAFETY_DEPTH = 10_000


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
        if not (isinstance(self.mixture_alpha, (int, float)) and 0.0 <= self.mixture_alpha <= 1.0):
            raise ValueError(f"mixture_alpha: expected a number in [0, 1], got {self.mixture_alpha!r}")
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
        delta = [n for n, m in zip(scene.materials.names, scene.materials.materials) if m.delta]
        lines.append(f"specular (delta) materials: {', '.join(delta)}: no light sampling at their vertices"
                     if delta else "no specular (delta) materials: no specular code runs")
        return lines

    def check(self, scene) -> None:
        """Raise ValueError if this estimator cannot render ``scene`` correctly."""
        if self.light_sampling in ("none", "mixture") and scene.lights.has_delta:
            raise ValueError(f"light_sampling={self.light_sampling!r} cannot reach point, spot or directional "
                             "lights (no ray can hit them); use 'mis' or 'nee'")

    # -- rendering ---------------------------------------------------------------------------------

    def render_item(self, scene, item: WorkItem, sampler, threads: int) -> ItemResult:
        """Trace one path per lane of ``item`` and return its pixel samples."""
        colours = RGBColours
        mesh, lights, accel, table = scene.mesh, scene.lights, scene.accel, scene.materials
        eps = np.float32(scene.ray_offset)
        options = {"diffuse_sampling": self.diffuse_sampling}
        strategy = self.light_sampling if lights.count else "none"
        env = lights.environment is not None

        n = item.pixels.size
        result = np.zeros((colours.channels, n))
        lane = np.arange(n)                            # wavefront slot of each live path
        radiance = np.zeros((colours.channels, n))    # radiance gathered so far by each live path
        beta = np.ones((colours.channels, n))         # path throughput
        pdf_prev = np.zeros(n)                         # solid-angle pdf of the sampled direction of the current ray
        delta_prev = np.ones(n, dtype=bool)            # previous vertex was the camera or a delta lobe
        u = sampler.draw(CAMERA_DIMS)
        origin, direction = scene.camera.generate_rays(item.pixels, u[0:2], u[2:4])
        prev_p = np.asarray(origin, dtype=np.float32)  # previous vertex (un-offset), for light pdfs
        rays = depth = truncated = 0
        while lane.size:
            depth += 1
            hits = accel.intersect(origin, direction, normals=False, threads=threads)
            rays += lane.size
            hit = hits.prim >= 0
            if env and not hit.all():
                self._escape(scene, ~hit, beta, radiance, pdf_prev, delta_prev, strategy, colours)
            alive = np.flatnonzero(hit)
            prim, t, b1, b2 = hits.prim, hits.t, hits.u, hits.v
            if alive.size < lane.size:
                _retire(result, lane, radiance, hit)
                lane, direction, beta, pdf_prev, delta_prev, radiance, prim, t, b1, b2, prev_p = _take(
                    alive, lane, direction, beta, pdf_prev, delta_prev, radiance, prim, t, b1, b2, prev_p)
                sampler.keep(alive)
                if not lane.size:
                    break
            p, normal = mesh.hit_geometry(prim, b1, b2)
            wo = -direction
            cos_o = dot(normal, wo)

            if lights.area.count:
                self._emission(scene, prim, p, cos_o, prev_p, beta, radiance, pdf_prev, delta_prev, strategy,
                               colours)

            if depth == self.max_depth:
                break
            if depth == SAFETY_DEPTH:
                truncated += lane.size
                break
            u = sampler.draw(DIMS_PER_BOUNCE)
            materials = MaterialLanes(table, mesh.material.take(prim), colours, options)
            if strategy in ("mis", "nee"):
                radiance += self._next_event(scene, materials, p, normal, wo, beta, u[0:3], eps, threads, colours)
                rays += lane.size

            sample = materials.sample(normal, wo, u[3:6])
            if strategy == "mixture":
                self._mixture(scene, materials, p, normal, wo, sample, u, eps, threads, colours)
            weight = sample.weight
            beta = beta * weight
            pdf_prev, delta_prev, direction = sample.pdf, sample.delta, sample.wi
            origin = offset_along(p, normal, dot(normal, direction), eps)
            prev_p = p

            survival = self.roulette.survival(depth, beta, weight)
            keep = np.maximum(np.maximum(weight[0], weight[1]), weight[2]) > 0
            if survival is not None:
                keep &= u[6] < survival
                np.divide(beta, survival, out=beta, where=survival > 0)
            live = np.flatnonzero(keep)
            if live.size < lane.size:
                _retire(result, lane, radiance, keep)
                lane, origin, direction, beta, pdf_prev, delta_prev, radiance, prev_p = _take(
                    live, lane, origin, direction, beta, pdf_prev, delta_prev, radiance, prev_p)
                sampler.keep(live)
        _retire(result, lane, radiance, np.zeros(lane.size, dtype=bool))
        return ItemResult(values=result, rays=rays, truncated=truncated)

    def _weight_of_hits(self, pdf_bsdf, pdf_light, delta_prev, strategy):
        """Weight of emission found by the current rays: MIS against light sampling, 1 where light
        sampling could not have produced it (camera rays, delta lobes), 0 for "nee" past those."""
        if strategy in ("none", "mixture"):
            return 1.0
        if strategy == "nee":
            return delta_prev.astype(np.float64)
        return np.where(delta_prev, 1.0, mis_weight(pdf_bsdf, pdf_light, self.mis, self.mis_beta))

    def _emission(self, scene, prim, p, cos_o, prev_p, beta, radiance, pdf_prev, delta_prev, strategy, colours):
        """Add emission of area lights hit by the current rays (Veach 1997, eq. 9.4 with 9.13)."""
        lights = scene.lights
        emitter = lights.area.emitter_of_triangle.take(prim)
        emits = np.flatnonzero(emitter >= 0)
        if not emits.size:
            return
        le = lights.area.emitted(emitter.take(emits), cos_o.take(emits), colours)
        if strategy == "mis":
            pdf_light = lights.pdf_hit(prim.take(emits), np.take(prev_p, emits, axis=1), np.take(p, emits, axis=1),
                                       self.light_selection, self.light_measure)
        else:
            pdf_light = None
        le = le * self._weight_of_hits(pdf_prev.take(emits), pdf_light, delta_prev.take(emits), strategy)
        radiance[:, emits] += np.take(beta, emits, axis=1) * le

    def _escape(self, scene, escaped, beta, radiance, pdf_prev, delta_prev, strategy, colours):
        """Add environment radiance to rays that left the scene."""
        lanes = np.flatnonzero(escaped)
        env = scene.lights.environment_radiance(lanes.size, colours)
        pdf_env = np.full(lanes.size, scene.lights.pdf_environment(self.light_selection))
        env = env * self._weight_of_hits(pdf_prev.take(lanes), pdf_env, delta_prev.take(lanes), strategy)
        radiance[:, lanes] += np.take(beta, lanes, axis=1) * env

    def _next_event(self, scene, materials, p, normal, wo, beta, u, eps, threads, colours):
        """Light-sampled direct illumination of every lane, MIS-weighted against BSDF sampling; (C, N).

        Estimates Le f |cos| / p_light (Veach 1997, eq. 9.4) with one light
        sample and one shadow ray per lane where the contribution is non-zero.
        Delta materials get nothing (f is zero for any light direction).
        """
        ls = scene.lights.sample(p, u, colours, self.light_selection, self.light_measure)
        f_cos, pdf_bsdf = materials.eval(normal, wo, ls.wi)
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = 1.0 / ls.pdf
        if self.light_sampling == "mis":
            w = mis_weight(ls.pdf, pdf_bsdf, self.mis, self.mis_beta)
            scale = scale * np.where(ls.delta, 1.0, w)
        contribution = beta * f_cos * (ls.value * scale)
        useful = np.flatnonzero(np.maximum(np.maximum(contribution[0], contribution[1]), contribution[2]) > 0)
        visible = np.zeros(p.shape[1], dtype=bool)
        if useful.size:
            wi = np.take(ls.wi, useful, axis=1)
            start = offset_along(np.take(p, useful, axis=1), np.take(normal, useful, axis=1),
                                 dot(np.take(normal, useful, axis=1), wi), eps)
            distance = ls.distance.take(useful)
            finite = np.isfinite(distance)
            if finite.all():
                end = offset_along(np.take(ls.point, useful, axis=1), np.take(ls.normal, useful, axis=1),
                                   ls.cos_light.take(useful), eps)
                blocked = scene.accel.occluded(start, end - start, 0.0, 1.0, threads=threads)
            else:
                # Point lights sit at `point` (no surface: no offset); infinite lights along wi without end.
                span = np.where(finite, distance * np.float32(1 - 1e-5), np.inf)
                blocked = scene.accel.occluded(start, wi, 0.0, span, threads=threads)
            visible[useful] = ~blocked
        return np.where(visible, contribution, 0.0)

    # -- mixture sampling --------------------------------------------------------------------------

    def _mixture(self, scene, materials, p, normal, wo, sample, u, eps, threads, colours) -> None:
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
        f_cos, pdf_bsdf = materials.eval(normal, wo, wi)
        origin = offset_along(p, normal, dot(normal, wi), eps)
        pdf_light = self._light_density(scene, p, origin, wi, threads)
        alpha = self.mixture_alpha
        pdf = alpha * pdf_light + (1.0 - alpha) * pdf_bsdf
        with np.errstate(divide="ignore", invalid="ignore"):
            weight = np.where(pdf > 0, f_cos / pdf, 0.0)
        delta = sample.delta
        sample.wi = wi
        sample.weight = np.where(delta, sample.weight, weight)
        sample.pdf = np.where(delta, sample.pdf, pdf)

    def _light_density(self, scene, receivers, origin, direction, threads):
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
        tmin = np.zeros(count, dtype=np.float32)
        o, d = origin, direction
        while lanes.size:
            h = emitters.intersect(o, d, tmin, np.inf, normals=False, threads=threads)
            found = np.flatnonzero(h.prim >= 0)
            lanes, o, d = lanes.take(found), np.take(o, found, axis=1), np.take(d, found, axis=1)
            prim, t = h.prim.take(found), h.t.take(found)
            tri = lights.area.triangles.take(prim)
            points = o + d * t
            total[lanes] += lights.pdf_hit(tri, np.take(receivers, lanes, axis=1), points, self.light_selection,
                                           self.light_measure)
            tmin = t * np.float32(1 + 1e-5) + np.float32(1e-30)
        return total


def _take(indices: np.ndarray, *arrays: np.ndarray) -> list[np.ndarray]:
    """The lanes ``indices`` of each array (lanes along the last axis)."""
    return [np.take(a, indices, axis=-1) for a in arrays]


def _retire(result: np.ndarray, lane: np.ndarray, radiance: np.ndarray, keep: np.ndarray) -> None:
    """Store the radiance of the paths that end here (where ``keep`` is False) in their wavefront slots."""
    done = np.flatnonzero(~keep)
    if done.size:
        slots = lane.take(done)
        for c in range(result.shape[0]):
            result[c].put(slots, radiance[c].take(done))
