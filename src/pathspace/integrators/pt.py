"""Path tracing (Kajiya 1986) over wavefronts, with next-event estimation and MIS.

Parameters
----------
max_depth : int, default -1
    Longest path in segments; -1 is unbounded (the full solution).  1 shows
    only emitters seen directly, 2 adds direct illumination.
light_sampling : "mis" (default), "nee" or "none"
    How emitters are reached after the first segment: "mis" combines
    next-event estimation (area sampling of a light chosen by power) with BSDF
    sampling by multiple importance sampling; "nee" uses next-event estimation
    alone (emitters hit by BSDF samples are ignored past the first segment);
    "none" uses BSDF sampling alone (lights are found by chance).
mis : "power" (default) or "balance"
    The MIS heuristic of "mis" light sampling (Veach 1997, eq. 9.13).
mis_beta : float, default 2
    Exponent of the power heuristic.
rr, rr_depth, rr_probability, rr_cap
    Russian roulette policy and its parameters (see :mod:`pathspace.roulette`);
    default: throughput-based survival (pbrt-v4's rule) from depth 5.

Every wavefront lane carries one path.  All live lanes are at the same depth,
so each bounce is a handful of array operations over the live lanes followed
by compaction; rays go to Embree in one batch per bounce (closest hits) plus
one batch of shadow rays.

Each path consumes 2 random numbers for the pixel position and 6 per bounce
(3 light sample, 2 BSDF sample, 1 roulette), drawn whether used or not, so a
replaying sampler sees the same dimensions in the same order.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import materials
from ..mis import HEURISTICS, mis_weight
from ..roulette import RussianRoulette
from ..vecmath import dot, offset_along
from .base import ItemResult, WorkItem

__all__ = ["PathTracer"]

LIGHT_SAMPLING = ("mis", "nee", "none")
DIMS_PER_BOUNCE = 6


@dataclass
class PathTracer:
    """Unidirectional path tracer; see the module docstring for the parameters."""

    max_depth: int = -1
    light_sampling: str = "mis"
    mis: str = "power"
    mis_beta: float = 2.0
    rr: str = "throughput"
    rr_depth: int = 5
    rr_probability: float = 0.5
    rr_cap: float = 1.0
    roulette: RussianRoulette = field(init=False, repr=False)

    name = "pt"
    pixel_local = True

    def __post_init__(self) -> None:
        if not (isinstance(self.max_depth, (int, np.integer)) and (self.max_depth == -1 or self.max_depth >= 1)):
            raise ValueError(f"max_depth: expected -1 (unbounded) or an integer >= 1, got {self.max_depth!r}")
        if self.light_sampling not in LIGHT_SAMPLING:
            raise ValueError(f"light_sampling: expected one of {LIGHT_SAMPLING}, got {self.light_sampling!r}")
        if self.mis not in HEURISTICS:
            raise ValueError(f"mis: expected one of {HEURISTICS}, got {self.mis!r}")
        if not (isinstance(self.mis_beta, (int, float)) and np.isfinite(self.mis_beta) and self.mis_beta > 0):
            raise ValueError(f"mis_beta: expected a finite number > 0, got {self.mis_beta!r}")
        self.roulette = RussianRoulette(self.rr, self.rr_depth, self.rr_probability, self.rr_cap)

    def plan(self, scene) -> list[str]:
        """What this estimator will do on ``scene``, and what it leaves out and why."""
        depth = "unbounded" if self.max_depth < 0 else self.max_depth
        lines = [f"path tracing, max_depth={depth}; {self.roulette.describe()}"]
        if scene.lights.count == 0:
            lines.append("no emitters in the scene: the image is black; light sampling skipped")
        elif self.light_sampling == "mis":
            lines.append(f"next-event estimation + BSDF sampling, {self.mis} heuristic"
                         + (f" (beta={self.mis_beta:g})" if self.mis == "power" else ""))
        else:
            lines.append({"nee": "next-event estimation only", "none": "BSDF sampling only"}[self.light_sampling])
        return lines

    def render_item(self, scene, item: WorkItem, sampler, threads: int) -> ItemResult:
        """Trace one path per pixel of ``item`` and return the pixel samples."""
        mesh, lights, accel = scene.mesh, scene.lights, scene.accel
        reflectance = scene.materials.reflectance
        eps = np.float32(scene.ray_offset)
        use_nee = self.light_sampling != "none" and lights.count > 0
        count_hits = lights.count > 0 and self.light_sampling != "nee"

        n = item.pixels.size
        result = np.zeros((3, n))
        lane = np.arange(n)                  # wavefront slot of each live path
        radiance = np.zeros((3, n))          # radiance gathered so far by each live path
        beta = np.ones((3, n))               # path throughput
        pdf_prev = np.zeros(n)               # solid-angle pdf of the direction that made the current ray
        origin, direction = scene.camera.generate_rays(item.pixels, sampler.draw(2))
        rays = depth = 0
        while lane.size:
            depth += 1
            hits = accel.intersect(origin, direction, normals=False, threads=threads)
            rays += lane.size
            prim, t, b1, b2 = hits.prim, hits.t, hits.u, hits.v
            alive = np.flatnonzero(prim >= 0)
            if alive.size < lane.size:
                _retire(result, lane, radiance, prim >= 0)
                lane, direction, beta, pdf_prev, radiance, prim, t, b1, b2 = _take(
                    alive, lane, direction, beta, pdf_prev, radiance, prim, t, b1, b2)
                sampler.keep(alive)
                if not lane.size:
                    break
            p, normal = mesh.hit_geometry(prim, b1, b2)
            cos_o = -dot(normal, direction)
            normal *= np.copysign(np.float32(1), cos_o)  # two-sided: the normal on the side of wo

            # Emission found by the camera ray or the BSDF-sampled ray (Veach 1997, eq. 9.4 with 9.13).
            if lights.count and (depth == 1 or count_hits):
                emits = np.flatnonzero(lights.emitter_of_triangle.take(prim) >= 0)
                if emits.size:
                    tri, cos_e = prim.take(emits), cos_o.take(emits)
                    le = lights.emitted(tri, cos_e)
                    if depth > 1 and self.light_sampling == "mis":
                        pdf_light = lights.pdf_sa(tri, t.take(emits), cos_e)
                        le *= mis_weight(pdf_prev.take(emits), pdf_light, self.mis, self.mis_beta)
                    radiance[:, emits] += np.take(beta, emits, axis=1) * le

            if depth == self.max_depth:
                break
            u = sampler.draw(DIMS_PER_BOUNCE)
            albedo = np.take(reflectance, scene.mesh.material.take(prim), axis=1)
            # Throughput after this vertex: the diffuse sample weight f |cos| / pdf is the albedo.
            beta_next = beta * albedo
            if use_nee:
                radiance += self._next_event(scene, threads, p, normal, beta_next, u[0:3], eps)
                rays += lane.size

            # Sample the next direction; reflection leaves on the side of the normal.
            direction, pdf_prev = materials.diffuse_sample(normal, u[3:5])
            beta = beta_next
            origin = p + normal * eps

            survival = self.roulette.survival(depth, beta, albedo)
            keep = np.maximum(np.maximum(albedo[0], albedo[1]), albedo[2]) > 0
            if survival is not None:
                keep &= u[5] < survival
                beta /= survival
            live = np.flatnonzero(keep)
            if live.size < lane.size:
                _retire(result, lane, radiance, keep)
                lane, origin, direction, beta, pdf_prev, radiance = _take(
                    live, lane, origin, direction, beta, pdf_prev, radiance)
                sampler.keep(live)
        _retire(result, lane, radiance, np.zeros(lane.size, dtype=bool))
        return ItemResult(values=result, rays=rays)

    def _next_event(self, scene, threads, p, normal, beta_albedo, u, eps) -> np.ndarray:
        """Light-sampled direct illumination of every lane, MIS-weighted against BSDF sampling; (3, N).

        Estimates Le f |cos| / p_light (Veach 1997, eq. 9.4) with one point on
        one light per lane and one shadow ray where the contribution is non-zero.
        ``beta_albedo`` is the path throughput times the albedo of the vertex.
        """
        ls = scene.lights.sample(p, u)
        cos_over_pi = materials.diffuse_cos_over_pi(dot(normal, ls.wi))
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(ls.facing, cos_over_pi / ls.pdf_sa, 0.0)
        if self.light_sampling == "mis":
            scale *= mis_weight(ls.pdf_sa, cos_over_pi, self.mis, self.mis_beta)
        useful = np.flatnonzero(scale > 0)
        if useful.size:
            start = np.take(p, useful, axis=1) + np.take(normal, useful, axis=1) * eps
            end = offset_along(np.take(ls.point, useful, axis=1), np.take(ls.normal, useful, axis=1),
                               ls.cos_light.take(useful), eps)
            blocked = scene.accel.occluded(start, end - start, 0.0, 1.0, threads=threads)
            scale[useful[blocked]] = 0.0
        scale[scale != scale] = 0.0  # NaN from degenerate light samples (receiver on the light)
        return beta_albedo * (ls.radiance * scale)


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
