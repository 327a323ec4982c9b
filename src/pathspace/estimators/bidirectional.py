"""What bidirectional estimators (light tracing, BDPT) share: batches of subpaths, weighting, splatting.

A work item's lanes (one per pixel and pass) each get a light subpath and,
for BDPT, a camera subpath.  Connections between them contribute either to
the lane's own pixel or, when they reach the camera through a lens sample
or a lens hit (t <= 1), to the pixel they land on: a *splat*.  Each pass
launches one light subpath per pixel, so the splats of a pass, summed per
pixel, estimate the image (pbrt's light-tracing normalisation: We integrates
to 1 over the film), and one pass gives one independent sample of every
pixel -- its own-pixel value plus the pass's splats.  Items hand the film
both, and the film completes a pass once all its tiles are in.

Random numbers come from three streams per (pass, tile) unit (see
:data:`STREAMS`): camera subpaths, light subpaths, and the lane's
wavelengths; connections use the uniforms drawn with their vertices.
:meth:`Bidirectional.evaluate` computes every strategy's contribution of the
paths made from given numbers.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable, Iterator, Mapping

import numpy as np

from ..roulette import RussianRoulette, roulette_warnings
from ..sampler import Sampler
from ..spectra import RGBColours, RGBMode
from . import parameters as p
from .base import Counters, Estimator, ItemResult, RenderJob, Splats, WorkItem
from .connections import Batch, Contributions
from .control import RenderControl
from .pt_fused import walk_vertex
from .subpaths import LIGHT_VERTEX, SAFETY_VERTICES, SubpathSettings, camera_subpaths, light_subpaths
from .wavefront import Lanes

__all__ = ["Bidirectional", "StrategyContributions", "STREAMS"]

# The random streams of a (pass, tile) unit, by name and the number appended to the unit's key.
STREAMS = {"camera": 0, "light": 1, "wavelengths": 2}


@dataclass
class StrategyContributions:
    """Every connection of a batch of lanes: ``lane``, strategy ``s``, ``t``, film values (3, n) ``unweighted``
    and ``weighted`` (by ``weight``), and the film ``pixel`` it lands on (``raster`` (2, n) position for
    splats, t <= 1; NaN for the lane's own pixel)."""

    lane: np.ndarray
    s: np.ndarray
    t: np.ndarray
    unweighted: np.ndarray
    weighted: np.ndarray
    weight: np.ndarray
    pixel: np.ndarray
    raster: np.ndarray

    @classmethod
    def concatenate(cls, parts: list["StrategyContributions"]) -> "StrategyContributions":
        """The rows of all ``parts``."""
        if not parts:
            empty = np.zeros(0, np.int64)
            return cls(empty, empty, empty, np.zeros((3, 0)), np.zeros((3, 0)), np.zeros(0), empty, np.zeros((2, 0)))
        return cls(*(np.concatenate([getattr(part, f) for part in parts], axis=-1) for f in
                     ("lane", "s", "t", "unweighted", "weighted", "weight", "pixel", "raster")))


@dataclass
class Bidirectional(Estimator):
    """Base of estimators built from light (and camera) subpaths; subclasses choose the connections.

    Its fields are the parameters all of them take (see :mod:`pathspace.estimators.bdpt`).
    """

    max_depth: int = p.max_depth()
    rr: str = p.roulette_policy("albedo")
    rr_depth: int = p.roulette_depth(1)
    rr_probability: float = p.roulette_probability()
    rr_cap: float = p.roulette_cap()
    light_rr: str | None = p.light_rr()
    light_rr_depth: int | None = p.light_rr_depth()
    light_rr_probability: float | None = p.light_rr_probability()
    light_rr_cap: float | None = p.light_rr_cap()
    diffuse_sampling: str = p.diffuse_sampling()
    pyramid: int = p.pyramid()
    kernel: str = p.kernel("the subpaths' vertices and their connections")
    roulette: RussianRoulette = field(init=False, repr=False)
    light_roulette: RussianRoulette = field(init=False, repr=False)

    uses_camera_subpaths = True
    uses_lens_hits = True
    uses_densities = True  # connections weighted by MIS, which reads the vertex densities (light tracing: no)

    def __post_init__(self) -> None:
        super().__post_init__()
        camera = RussianRoulette(self.rr, self.rr_depth, self.rr_probability, self.rr_cap)
        light = RussianRoulette(*(own if own is not None else shared for own, shared in (
            (self.light_rr, self.rr), (self.light_rr_depth, self.rr_depth),
            (self.light_rr_probability, self.rr_probability), (self.light_rr_cap, self.rr_cap))))
        camera_in_mis, light_in_mis = self._roulette_in_mis(light)
        self.roulette, self.light_roulette = replace(camera, in_mis=camera_in_mis), replace(light, in_mis=light_in_mis)

    def _roulette_in_mis(self, light: RussianRoulette) -> tuple[bool, bool]:
        """Whether the camera and the light subpaths' local roulette enter the vertex densities, given the light
        subpaths' ``light`` (both here)."""
        return True, True

    def _walk_plan(self, scene) -> str:
        """Where the subpaths' vertices (BSDF sample, roulette) are taken on ``scene``."""
        fused, reason = walk_vertex(scene, RGBColours, self.light_roulette, {"diffuse_sampling": self.diffuse_sampling},
                                    LIGHT_VERTEX, "importance", self.uses_densities, self.kernel)
        return ("subpath vertices in one C pass (a fused kernel) in RGB, in NumPy when spectral" if fused is not None
                else f"subpath vertices in NumPy ({reason})")

    def _roulette_plan(self) -> str:
        if not self.uses_densities:
            return f"{self.light_roulette.describe()} on the subpaths"
        walks = [name for name, roulette in (("camera", self.roulette), ("light", self.light_roulette))
                 if roulette.in_mis and roulette.local and roulette.policy != "off"]
        densities = (f"in the vertex densities MIS compares: the {' and '.join(walks)} subpaths' survival" if walks
                     else "no survival probabilities in the vertex densities MIS compares")
        if self.roulette.samples_like(self.light_roulette):
            return f"{self.light_roulette.describe()} on the subpaths ({densities})"
        return (f"camera subpaths: {self.roulette.describe()}; light subpaths: {self.light_roulette.describe()} "
                f"({densities})")

    def warnings(self, scene) -> list[str]:
        """Roulette settings with infinite variance on ``scene``."""
        found = roulette_warnings(self.light_roulette, scene.materials, self.max_depth)
        if self.uses_camera_subpaths and not self.roulette.samples_like(self.light_roulette):
            found = roulette_warnings(self.roulette, scene.materials, self.max_depth) + found
        return found

    @property
    def depth_limit(self) -> int:
        """Longest path in segments that connections may form."""
        return self.max_depth if self.max_depth > 0 else SAFETY_VERTICES

    def film_layers(self, scene) -> int:
        """The most per-strategy layers a render of ``scene`` records: a weighted and an unweighted one per
        strategy (s, t) of every path length up to ``pyramid`` -- t = 1 only without camera subpaths, no
        t = 0 with a pinhole camera (see :meth:`_record_strategies`)."""
        lengths = range(1, min(self.pyramid, self.depth_limit) + 1)
        if not self.uses_camera_subpaths:
            return 2 * len(lengths)
        return 2 * sum(length + 2 - bool(scene.camera.delta_position) for length in lengths)

    def _contributions(self, batch: Batch) -> Iterator[Contributions]:
        """The unweighted contributions of the strategies this estimator uses, part by part."""
        raise NotImplementedError

    def _weights(self, part: Contributions, batch: Batch) -> np.ndarray:
        """The MIS weight of every connection of ``part``."""
        raise NotImplementedError

    # -- rendering ---------------------------------------------------------------------------------

    def render_items(self, job: RenderJob, next_item: Callable[[], WorkItem | None],
                     counters: Counters) -> Iterator[ItemResult]:
        """Render each item ``next_item()`` hands out as one batch of subpaths."""
        while (item := next_item()) is not None:
            yield self._render_item(job, item, counters)

    def _render_item(self, job: RenderJob, item: WorkItem, counters: Counters) -> ItemResult:
        scene, mode = job.scene, job.mode
        pixels = item.pixels
        count = pixels.size
        result = ItemResult(item, np.zeros((3, count)))
        if not scene.lights.count:
            return result
        samplers = {name: job.samplers.open([key + (code,) for key in item.keys], item.counts)
                    for name, code in STREAMS.items()}
        units = np.arange(0, count + 1, item.pixel_stop - item.pixel_start)
        batch, state = self._subpaths(scene, mode, pixels, samplers, units, counters, job.control)
        own = np.zeros((batch.colours.channels, count))
        for part in self._contributions(batch):
            job.control.check()
            _, weighted, pixel, splat = self._weighted(part, batch, pixels)
            mine = np.flatnonzero(~splat)
            if mine.size:
                lane, values = ((part.lane, weighted) if mine.size == part.count
                                else (part.lane.take(mine), np.take(weighted, mine, axis=1)))
                for c in range(batch.colours.channels):
                    own[c] += np.bincount(lane, weights=values[c], minlength=count)
            if mine.size < part.count:
                on = np.flatnonzero(splat)
                result.splats.append(Splats(item.pass_of(part.lane[on]), pixel[on],
                                            mode.to_film(np.take(weighted, on, axis=1), state, part.lane[on])))
            if self.pyramid:
                self._record_strategies(result.layers, part, weighted, pixel, mode, state, item)
        counters.rays += batch.rays
        counters.nonfinite_contributions += batch.nonfinite
        result.samples = mode.to_film(own, state, np.arange(count))
        return result

    def evaluate(self, scene, pixels: np.ndarray, samplers: Mapping[str, Sampler], mode=None,
                 counters: Counters | None = None, chosen: tuple[np.ndarray, np.ndarray] | None = None
                 ) -> StrategyContributions:
        """Every strategy's contribution of the paths through ``pixels`` (N,) built from given numbers:
        ``samplers`` has a sampler of N lanes for each stream of :data:`STREAMS` (e.g.
        :class:`~pathspace.sampler.ReplaySampler` s of primary samples).  The weighted values of a lane's
        own pixel (``raster`` NaN) plus its splats are the samples a render adds for these numbers.  Rays,
        subpath lengths and dropped connections are counted into ``counters`` if given.  ``chosen`` = (s, t)
        per lane: compute only that strategy of each lane, with subpaths of at most t camera and s light
        vertices (multiplexed MLT)."""
        mode = RGBMode() if mode is None else mode
        pixels = np.asarray(pixels, dtype=np.int64)
        if not scene.lights.count:
            return StrategyContributions.concatenate([])
        counters = Counters() if counters is None else counters
        batch, state = self._subpaths(scene, mode, pixels, samplers, np.array([0, pixels.size]), counters,
                                      RenderControl(), chosen)
        rows = []
        for part in self._contributions(batch):
            weights, weighted, pixel, _ = self._weighted(part, batch, pixels)
            rows.append(StrategyContributions(part.lane, part.s, part.t, mode.to_film(part.value, state, part.lane),
                                              mode.to_film(weighted, state, part.lane), weights, pixel, part.raster))
        counters.rays += batch.rays
        counters.nonfinite_contributions += batch.nonfinite
        return StrategyContributions.concatenate(rows)

    def _subpaths(self, scene, mode, pixels: np.ndarray, samplers: Mapping[str, Sampler], units: np.ndarray,
                  counters: Counters, control: RenderControl,
                  chosen: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[Batch, Lanes]:
        """The subpaths of lanes through ``pixels`` from ``samplers``' numbers, and the lanes' colour state
        (for ``chosen`` strategies, see :meth:`evaluate`)."""
        count = pixels.size
        state, settings = self._walk_settings(scene, mode, samplers, counters, control)
        colours = settings.colours
        s, t = chosen if chosen is not None else (None, None)
        eye = (camera_subpaths(settings, pixels, samplers["camera"], None if t is None else np.maximum(t, 1))
               if self.uses_camera_subpaths else None)
        lens = self.uses_lens_hits and not scene.camera.delta_position
        light, hits = light_subpaths(settings, count, samplers["light"], lens, None if s is None else np.maximum(s, 1))
        longest = max(int(light.length.max()), 0 if eye is None else int(eye.length.max())) - 1
        counters.longest = max(counters.longest, longest)
        terminated = light.terminated if eye is None else light.terminated | eye.terminated
        if terminated.any():
            mode.terminate_secondary(state, terminated)
        return Batch(scene, light, eye, hits if lens else None, colours, settings.options, self.depth_limit,
                     units, self.uses_densities, chosen=chosen, **self._kernels(scene, settings)), state

    def _kernels(self, scene, settings: SubpathSettings) -> dict:
        """The fused C kernels of a batch's connections on ``scene`` with ``settings`` (the :class:`Batch` fields
        ``lens_kernel``, ``join_kernel`` and ``light_kernel``) that this estimator uses and that serve the scene;
        none here."""
        return {}

    def _walk_settings(self, scene, mode, samplers: Mapping[str, Sampler], counters: Counters,
                       control: RenderControl) -> tuple[Lanes, SubpathSettings]:
        """The lanes' colour state (their wavelengths, from ``samplers``) and what their subpath walks share."""
        state = Lanes(mode.path_fields, **mode.start(samplers["wavelengths"].draw(mode.camera_dims)))
        settings = SubpathSettings(scene, mode.colours(state), {"diffuse_sampling": self.diffuse_sampling},
                                   self.roulette, self.light_roulette, self.depth_limit + 1, counters, control,
                                   self.uses_densities, self.kernel)
        return state, settings

    def _weighted(self, part: Contributions, batch: Batch, pixels: np.ndarray):
        """(MIS weights (n,), weighted values (C, n), film pixel (n,), whether each is a splat (n,)) of ``part``'s
        connections; connections whose weight is not finite are dropped and counted like non-finite values."""
        weights = self._weights(part, batch)
        finite = np.isfinite(weights)
        if not finite.all():
            batch.nonfinite += int(finite.size - np.count_nonzero(finite))
            weights = np.where(finite, weights, 0.0)
        splat = np.isfinite(part.raster[0])
        if not splat.any():   # a family of strategies gives only splats (t <= 1) or none
            pixel = pixels.take(part.lane)
        elif splat.all():
            pixel = batch.scene.camera.pixel_of(part.raster)
        else:
            pixel = np.where(splat, batch.scene.camera.pixel_of(part.raster), pixels.take(part.lane))
        return weights, part.value * weights[None, :], pixel, splat

    def _record_strategies(self, layers: dict, part: Contributions, weighted: np.ndarray, film_pixel, mode,
                           state, item: WorkItem) -> None:
        """Unweighted and weighted contributions per strategy (s, t) of paths up to ``pyramid`` segments, as
        splats into the layers ``s{s}t{t}.unweighted`` and ``s{s}t{t}.weighted``."""
        length = part.s + part.t - 1
        for s, t in {(int(a), int(b)) for a, b in zip(part.s[length <= self.pyramid], part.t[length <= self.pyramid])}:
            pick = np.flatnonzero((part.s == s) & (part.t == t))
            lanes = part.lane.take(pick)
            passes, pixels = item.pass_of(lanes), film_pixel.take(pick)   # shared by both layers (read only)
            for kind, value in (("unweighted", part.value), ("weighted", weighted)):
                film = mode.to_film(np.take(value, pick, axis=1), state, lanes)
                layers.setdefault(f"s{s}t{t}.{kind}", []).append(Splats(passes, pixels, film))
