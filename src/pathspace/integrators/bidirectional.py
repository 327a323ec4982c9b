"""What bidirectional estimators (light tracing, BDPT) share: batches of subpaths, weighting, splatting.

A work item's lanes (one per pixel and pass) each get a light subpath and,
for BDPT, a camera subpath.  Connections between them contribute either to
the lane's own pixel or, when they reach the camera through a lens sample
or a lens hit (t <= 1), to the pixel they land on: a *splat*.  Each pass
launches one light subpath per pixel, so the splats of a pass, summed per
pixel, estimate the image (pbrt's light-tracing normalisation: We integrates
to 1 over the film), and one pass gives one independent sample of every
pixel -- its own-pixel value plus the pass's splats.  Items therefore return
both, and the driver adds a pass to the film once all its tiles are in.

Random numbers come from three streams per (pass, tile): camera subpaths,
light subpaths, and the lane's wavelengths; connections use the uniforms
drawn with their vertices.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..bsdfs import DIFFUSE_SAMPLING
from ..sampler import StreamSampler
from .base import TILE_PIXELS, WorkItem
from .connections import Batch, Contributions
from .subpaths import ROULETTE, SAFETY_VERTICES, camera_subpaths, continuation, light_subpaths
from .wavefront import Lanes

__all__ = ["Bidirectional"]

CAMERA_STREAM, LIGHT_STREAM, LANE_STREAM = 0, 1, 2
EMISSION_UNIFORMS = 5 + 2  # light choice, point, direction (5); the lens sample of vertex 0 (2)


@dataclass
class Bidirectional:
    """Base of estimators built from light (and camera) subpaths; subclasses choose the connections.

    Its fields are the parameters all of them take (see :mod:`pathspace.integrators.bdpt`).
    """

    max_depth: int = -1
    rr: str = "albedo"
    rr_probability: float = 0.5
    diffuse_sampling: str = "cosine"
    pyramid: int = 0

    # Items of at most this many pixels: larger items spend less time in Python per sample (65536 lanes:
    # 5% faster than 32768 on the Cornell box, about 0.5 GB at two threads; 131072 is slower again).
    tile_pixels = TILE_PIXELS
    uses_camera_subpaths = True

    def __post_init__(self) -> None:
        if not (isinstance(self.max_depth, (int, np.integer)) and (self.max_depth == -1 or self.max_depth >= 1)):
            raise ValueError(f"max_depth: expected -1 (unbounded) or an integer >= 1, got {self.max_depth!r}")
        if self.rr not in ROULETTE:
            raise ValueError(f"rr: expected one of {ROULETTE}, got {self.rr!r}")
        if not (isinstance(self.rr_probability, (int, float)) and 0.0 <= self.rr_probability < 1.0):
            raise ValueError(f"rr_probability: expected a termination probability in [0, 1), got "
                             f"{self.rr_probability!r}")
        if self.diffuse_sampling not in DIFFUSE_SAMPLING:
            raise ValueError(f"diffuse_sampling: expected one of {DIFFUSE_SAMPLING}, got {self.diffuse_sampling!r}")
        if not (isinstance(self.pyramid, (int, np.integer)) and self.pyramid >= 0):
            raise ValueError(f"pyramid: expected an integer >= 0 (path length in segments), got {self.pyramid!r}")

    def prepare(self, scene) -> None:
        """Build the acceleration structures this estimator uses on ``scene``."""
        scene.accel

    @property
    def depth_limit(self) -> int:
        """Longest path in segments that connections may form."""
        return self.max_depth if self.max_depth > 0 else SAFETY_VERTICES

    def render_stream(self, scene, next_item, seed: int, mode, counters: dict):
        """Render items from ``next_item()`` until it returns None.

        Yields (item, own-pixel film values (3, n), splat images (passes in the
        item, 3, pixels), per-strategy sums {(s, t): (2, 3, pixels)} --
        unweighted and weighted -- or None when ``pyramid`` is 0).
        """
        q_table = continuation(scene, self.rr, self.rr_probability)
        options = {"diffuse_sampling": self.diffuse_sampling}
        while (item := next_item()) is not None:
            yield self._render_item(scene, item, seed, mode, counters, q_table, options)

    def _render_item(self, scene, item: WorkItem, seed: int, mode, counters: dict, q_table, options) -> tuple:
        camera = scene.camera
        count = item.pixels.size
        width = item.pixel_stop - item.pixel_start
        pixels = camera.pixel_count
        splats = np.zeros((len(item.passes), 3, pixels))
        if not scene.lights.count:
            return item, np.zeros((3, count)), splats, None
        max_vertices = self.depth_limit + 1

        def stream(role: int, dims: int):
            sampler = StreamSampler(seed)
            return sampler, sampler.add([key + (role,) for key in item.keys], item.counts, dims)

        _, u = stream(LANE_STREAM, mode.camera_dims)
        state = Lanes(mode.path_fields, **mode.start(u))
        colours = mode.colours(state)
        eye = None
        if self.uses_camera_subpaths:
            sampler, u = stream(CAMERA_STREAM, 4)
            eye, rays = camera_subpaths(scene, item.pixels, u, sampler, colours, options, q_table, max_vertices,
                                        counters)
            counters["rays"] += rays
        sampler, u = stream(LIGHT_STREAM, EMISSION_UNIFORMS)
        lens = self.uses_lens_hits and not camera.delta_position
        light, hits, rays = light_subpaths(scene, u, sampler, colours, options, q_table, max_vertices, lens, counters)
        counters["rays"] += rays
        longest = max(int(light.length.max()), 0 if eye is None else int(eye.length.max())) - 1
        counters["longest"] = max(counters["longest"], longest)
        terminated = light.terminated if eye is None else light.terminated | eye.terminated
        if terminated.any():
            mode.terminate_secondary(state, terminated)
        batch = Batch(scene, light, eye, hits if lens else None, colours, options, self.depth_limit)

        own = np.zeros((colours.channels, count))
        strategies: dict | None = {} if self.pyramid else None
        for part in self._contributions(batch):
            weights = self._weights(part, batch)
            finite = np.isfinite(weights)
            if not finite.all():  # from non-finite densities: dropped and counted like non-finite values
                batch.nonfinite += int(finite.size - np.count_nonzero(finite))
                weights = np.where(finite, weights, 0.0)
            weighted = part.value * weights[None, :]
            splat = np.isfinite(part.raster[0])
            mine = np.flatnonzero(~splat)
            if mine.size:
                for c in range(colours.channels):
                    own[c] += np.bincount(part.lane[mine], weights=weighted[c, mine], minlength=count)
            film_pixel = np.where(splat, _pixel_of(part.raster, camera), item.pixels.take(part.lane))
            if mine.size < part.count:
                on = np.flatnonzero(splat)
                values = mode.to_film(weighted[:, on], state, part.lane[on])
                slot = (part.lane[on] // width) * pixels + film_pixel[on]
                for c in range(3):
                    splats[:, c] += np.bincount(slot, weights=values[c], minlength=splats.shape[0] * pixels
                                                ).reshape(splats.shape[0], pixels)
            if strategies is not None:
                self._record_strategies(strategies, part, weighted, film_pixel, mode, state, pixels)
        counters["rays"] += batch.rays
        counters["nonfinite_contributions"] += batch.nonfinite
        return item, mode.to_film(own, state, np.arange(count)), splats, strategies

    def _record_strategies(self, strategies: dict, part: Contributions, weighted: np.ndarray, film_pixel, mode,
                           state, pixels: int) -> None:
        """Add unweighted and weighted contributions per strategy (s, t) of paths up to ``pyramid`` segments."""
        length = part.s + part.t - 1
        for s, t in {(int(a), int(b)) for a, b in zip(part.s[length <= self.pyramid], part.t[length <= self.pyramid])}:
            pick = np.flatnonzero((part.s == s) & (part.t == t))
            sums = strategies.setdefault((s, t), np.zeros((2, 3, pixels)))
            for k, value in enumerate((part.value, weighted)):
                film = mode.to_film(np.take(value, pick, axis=1), state, part.lane.take(pick))
                for c in range(3):
                    sums[k, c] += np.bincount(film_pixel.take(pick), weights=film[c], minlength=pixels)


def _pixel_of(raster: np.ndarray, camera) -> np.ndarray:
    """Pixel index of raster positions (NaN rows give 0; callers mask them)."""
    x = np.clip(np.nan_to_num(raster[0]), 0, camera.width - 1).astype(np.int64)
    y = np.clip(np.nan_to_num(raster[1]), 0, camera.height - 1).astype(np.int64)
    return y * camera.width + x
