"""Veach's path-space Metropolis light transport (Veach & Guibas 1997; Veach 1997, ch. 11).

A chain's state is a path x_0 .. x_k itself (:mod:`pathspace.estimators.paths`),
and the chains sample paths in proportion to c(f(x)) (c: luminance Y by
default) by a mixture of Veach's mutations
(:mod:`pathspace.estimators.path_mutations`).  Bidirectional mutations make
the chains ergodic; the perturbations explore near a path (the lens
perturbation moves what the camera sees, the caustic perturbation moves
where light through specular chains lands, the multi-chain perturbation
moves caustics seen through specular chains).

Each step chooses, per chain, among the mutations that can move its path x:
the bidirectional mutation always, a perturbation only where x has the
vertices it moves.  The probabilities p_m(x) are the weights
``bidirectional`` : ``lens`` : ``caustic`` : ``multichain`` of those mutations,
normalised, so no step is spent proposing a perturbation that cannot apply.
A proposal y is accepted with a = min(1, c(f(y)) T(y -> x) / (c(f(x)) T(x -> y)))
(Veach 1997, eq. 11.3), the transition densities computed exactly and
including the choice: T(x -> y) = p_m(x) T_m(x -> y) (Metropolis-Hastings
with a state-dependent mixture, Hastings 1970).  A perturbation keeps the
length and the specular vertices of a path, and with them the mutations
that apply, so p_m(y) = p_m(x) cancels; a bidirectional mutation can change
them, and its ratio carries p_b(y) / p_b(x).

As Veach recommends (sec. 11.5), short paths -- emitters seen directly and
direct lighting, and by default everything up to ``direct`` = 4 segments,
such as a caustic seen directly -- are not left to the chains: each pass
renders them with BDPT (``max_depth = direct``, one sample per pixel), and
the chains sample only longer paths, where exploring pays.  With
``explore='specular'`` they sample only the longer paths with a specular
vertex, and the BDPT pass (to ``max_depth``) renders the others.

Normalisation and start (sec. 11.3.1).  Each path length L (``direct`` + 1
.. ``max_depth``) is a class with ``bootstrap`` independent samples, each a
pair of a light walk and a camera walk joined in all L + 1 ways, as BDPT
does (:func:`~pathspace.estimators.path_mutations.fresh_paths`): the paths,
weighted by f / sum_j p_j, estimate the energy b_L of paths of length L
(multi-sample balance heuristic).  Chains are shared out in
proportion to b_L and start at paths drawn in proportion to c(f) / sum_j p_j;
each chain's splats are scaled by P b_L / (chains of its length), as in
:mod:`pathspace.estimators.metropolis`, whose expected-value splatting and
statistics it shares.  Chains change length freely.

Spectral renders carry each path's wavelengths as one more number of the
state (moved by a small step with every bidirectional mutation).  Scope:
scenes lit by area lights and seen by a pinhole camera (the camera vertex is
never mutated); for point, spot, directional or environment lights or a thin
lens use ``mmlt`` or ``pssmlt``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from typing import Callable

import numpy as np

from ..checks import choice, integer, number
from ..lights.area import AreaLight
from .base import Budget, Counters, Estimator, RenderJob, parameter
from .bdpt import BDPT
from .bidirectional import STREAMS
from .bootstrap import BATCH, GROUPS, allocate, reservoir_draw
from .control import Interrupted, RenderControl
from .metropolis import (CHAINS, CONTRIBUTIONS, Proposal, Splatting, chain_statistics, contribution_function,
                         run_passes, step_groups, uniform_stream)
from . import parameters as p
from .parameters import or_none
from .partition import UnexploredBDPT
from . import path_mutations as mutations
from .path_mutations import ADD_SPREAD, FreshPaths, Lengths, Proposed, fresh_paths
from .paths import Paths, PathValues, Space
from .primary import Uniforms
from .workers import in_rounds, split

__all__ = ["MLT", "PathChains", "choice_ratio", "choose", "mutation_odds"]

MUTATIONS = ("bidirectional", "lens", "caustic", "multichain")
EXPLORE = ("all", "specular")
# r1 of the lens (and multi-chain) perturbation, pixels; r2 is LENS_FRACTION of the larger film side.  Veach's
# 0.1 pixel and 10% gave 9-10% more error at 30 s than these on the 128 x 128 caustic and ajar-door scenes (every
# seed of four; the pool the same; README, "Lens perturbation size").
LENS_RADIUS = 0.5
LENS_FRACTION = 0.05
# Paths of at most this many segments go to BDPT by default: on the caustic and ajar-door scenes (benchmarks/mlt.py,
# 128 x 128, max_depth 10) time to relMSE 1e-2 is 2.4x and 0.71x BDPT's with 4, 13x and 0.96x with Veach's 2.
DIRECT = 4
CAUSTIC_ANGLE = (1e-4, 0.1)   # theta1, theta2 of the caustic perturbation, radians (Veach 1997, sec. 11.4.4)
# Random streams of a render (the first number of each unit key).
_BOOTSTRAP, _CHAINS, _DIRECT = 0, 1, 2


@dataclass
class Bootstrap:
    """Per path length (class): ``brightness`` b_L, its ``standard_error``; the chains' starting paths, their
    values and ``label`` (class)."""

    brightness: np.ndarray
    standard_error: np.ndarray
    paths: Paths
    values: PathValues | None      # None without chains
    label: np.ndarray

    def part(self, chains: slice) -> "Bootstrap":
        """The starts of the chains ``chains`` (the brightness is the whole render's)."""
        lanes = np.arange(chains.start, chains.stop)
        return Bootstrap(self.brightness, self.standard_error, self.paths.take(lanes), self.values.take(lanes),
                         self.label[chains])


class PathChains(Splatting):
    """Path-space chains: their paths, values, and one mutation of every chain per :meth:`step_all`."""

    def __init__(self, space: Space, estimator: "MLT", contribution, start: Bootstrap, scale: np.ndarray, pixels: int,
                 uniforms) -> None:
        super().__init__(scale, pixels, 3, MUTATIONS)
        self.space, self.lengths, self.contribution, self.uniforms = space, estimator.lengths, contribution, uniforms
        self.weights = estimator.weights
        self.paths, self.values = start.paths, start.values
        self.f = contribution(self.values.f)
        # p_m(x) of the current paths: it changes only where a bidirectional mutation is accepted (perturbations
        # keep what it depends on), so it is kept rather than recomputed every step.
        self.odds = mutation_odds(self.weights, self.paths, self.values)
        self.current = Proposal(np.arange(self.paths.count), self.values.pixel, self.values.f)
        camera = space.scene.camera
        self.lens_radius = (LENS_RADIUS, max(LENS_RADIUS, LENS_FRACTION * max(camera.width, camera.height)))

    def _mutate(self, kind: int, x: Paths, xv: PathValues) -> Proposed:
        if kind == 0:
            return mutations.bidirectional(self.space, self.lengths, x, xv, self.uniforms)
        if kind == 1:
            return mutations.lens(self.space, x, xv, self.uniforms, self.lens_radius)
        if kind == 2:
            return mutations.caustic(self.space, x, xv, self.uniforms, CAUSTIC_ANGLE)
        return mutations.multichain(self.space, x, xv, self.uniforms, self.lens_radius, CAUSTIC_ANGLE)

    def step_all(self, image: np.ndarray, counters: Counters) -> None:
        """One mutation of every chain, splatting into ``image`` (3, pixels)."""
        n = self.paths.count
        u = self.uniforms(2 * n).reshape(2, n)
        kind = choose(self.odds, u[0])
        f_new, accept_p = np.zeros(n), np.zeros(n)
        value, pixel = np.zeros((3, n)), np.zeros(n, np.int64)
        proposals = {}
        for code in np.unique(kind):
            lanes = np.flatnonzero(kind == code)
            # Slots the paths and their proposals can use (a bidirectional mutation adds at most ADD_SPREAD).
            slots = min(self.paths.slots, int(self.paths.k[lanes].max()) + 1 + ADD_SPREAD)
            proposed = self._mutate(int(code), self.paths.take(lanes, slots), self.values.take(lanes, slots))
            odds = None
            if code == 0:
                odds = mutation_odds(self.weights, proposed.paths, proposed.values)
                proposed.ratio = proposed.ratio * choice_ratio(self.odds[0].take(lanes), odds[0])
            c = self.contribution(proposed.values.f)
            finite = np.isfinite(proposed.values.f).all(axis=0) & np.isfinite(c)
            counters.nonfinite_contributions += int(finite.size - np.count_nonzero(finite))
            c = np.where(finite & (proposed.ratio > 0), c, 0.0)
            with np.errstate(divide="ignore", invalid="ignore"):
                a = np.where(self.f[lanes] > 0, np.minimum(1.0, c * proposed.ratio / self.f[lanes]), 1.0)
            f_new[lanes], accept_p[lanes] = c, np.where(c > 0, a, 0.0)
            value[:, lanes] = np.where(finite, proposed.values.f, 0.0)
            pixel[lanes] = proposed.values.pixel
            proposals[int(code)] = (lanes, proposed, odds)
        self.propose(image, Proposal(np.arange(n), pixel, value), f_new, accept_p)
        accept = u[1] < accept_p
        self.settle(image, accept, kind, MUTATIONS)
        for lanes, proposed, odds in proposals.values():
            taken = np.flatnonzero(accept.take(lanes))
            if taken.size:
                self.paths.assign(lanes.take(taken), proposed.paths.take(taken))
                self.values.assign(lanes.take(taken), proposed.values.take(taken))
                if odds is not None:
                    self.odds[:, lanes.take(taken)] = np.take(odds, taken, axis=1)
        self.f = np.where(accept, f_new, self.f)
        self.current = Proposal(np.arange(n), self.values.pixel, self.values.f)


def mutation_odds(weights: np.ndarray, x: Paths, xv: PathValues) -> np.ndarray:
    """(mutations, n): the probability p_m(x) of each mutation (:data:`MUTATIONS` order) at each of paths ``x``:
    ``weights`` of the mutations that can move the path (the bidirectional one always, each perturbation where
    :func:`~pathspace.estimators.path_mutations.perturbable`), normalised per path.  The bidirectional weight
    must be > 0 (as :class:`MLT` requires), so that every path has a mutation."""
    odds = weights[:, None] * np.vstack([np.ones((1, x.count), bool), mutations.perturbable(x, xv)])
    return odds / odds.sum(axis=0)


def choose(odds: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The mutation (row of ``odds``, (mutations, n)) each uniform ``u`` (n,) picks; never one of probability 0."""
    below = (np.cumsum(odds, axis=0) <= u).sum(axis=0)
    last = odds.shape[0] - 1 - np.argmax(odds[::-1] > 0, axis=0)   # the last possible one, should rounding pass it
    return np.minimum(below, last)


def choice_ratio(bidirectional_x: np.ndarray, bidirectional_y: np.ndarray) -> np.ndarray:
    """p_b(y) / p_b(x) of bidirectional mutations x -> y: the reverse move is chosen at y with y's odds
    (``bidirectional_x``, ``bidirectional_y``: the bidirectional row of :func:`mutation_odds` at x and y)."""
    return bidirectional_y / bidirectional_x


def _mutation_weight(value, name):
    return number(value, name, low=0.0, what="a weight >= 0")


@dataclass
class MLT(Estimator):
    """Veach's path-space MLT; see the module docstring for the method."""

    name = "mlt"
    independent_passes = False

    max_depth: int = parameter(16, "longest path in segments (each length has its own chains)",
                               partial(integer, low=1))
    direct: int | None = parameter(None, "paths of at most this many segments are rendered by BDPT each pass, not "
                                         "by the chains (Veach's direct lighting, extended); default: 4, or "
                                         "max_depth - 1 if smaller; 0: the chains render every length",
                                   or_none(partial(integer, low=0)))
    chains: int = parameter(CHAINS, "Markov chains, stepped in groups of at most 16384 (one wavefront each) on the "
                                    "render's threads", partial(integer, low=1))
    bootstrap: int = parameter(1 << 14, "independent samples per path length (pairs of a light and a camera "
                                        "walk, joined in every way) that estimate its brightness and the chains' "
                                        "starting paths", partial(integer, low=1))
    bidirectional: float = parameter(0.3, "weight of the bidirectional mutation (must be > 0: it alone reaches "
                                           "every path)", _mutation_weight)
    lens: float = parameter(0.5, "weight of the lens perturbation", _mutation_weight)
    caustic: float = parameter(0.1, "weight of the caustic perturbation", _mutation_weight)
    multichain: float = parameter(0.1, "weight of the multi-chain perturbation", _mutation_weight)
    contribution: str = parameter("luminance", "the scalar the chains sample: 'luminance' (Y), 'xyz' (X + Y + Z) "
                                               "or 'max' (largest channel)", partial(choice, options=CONTRIBUTIONS))
    explore: str = parameter("all", "which paths longer than direct the chains sample: 'all', or 'specular' (those "
                                    "with a specular vertex; BDPT renders the others each pass, one sample per "
                                    "pixel)", partial(choice, options=EXPLORE))
    kernel: str = p.kernel("the vertices and connections of the BDPT that renders the paths the chains leave")
    lengths: Lengths = field(init=False, repr=False)
    direct_estimator: BDPT | None = field(init=False, repr=False)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.direct is None:
            self.direct = min(DIRECT, self.max_depth - 1)
        if self.bidirectional <= 0:
            raise ValueError("bidirectional: expected a weight > 0 (without bidirectional mutations the chains "
                             f"cannot change a path's length or specular structure), got {self.bidirectional!r}")
        if self.direct >= self.max_depth:
            raise ValueError(f"direct: expected fewer segments than max_depth = {self.max_depth} (the chains render "
                             f"lengths direct + 1 .. max_depth), got {self.direct!r}")
        self.lengths = Lengths(self.max_depth, self.direct + 1)
        if self.explore == "specular":
            self.direct_estimator = UnexploredBDPT(max_depth=self.max_depth, direct=self.direct, kernel=self.kernel)
        else:
            self.direct_estimator = BDPT(max_depth=self.direct, kernel=self.kernel) if self.direct else None

    @property
    def weights(self) -> np.ndarray:
        """The mutations' probabilities, in :data:`MUTATIONS` order."""
        weights = np.array([self.bidirectional, self.lens, self.caustic, self.multichain])
        return weights / weights.sum()

    def plan(self, scene) -> list[str]:
        """What the chains explore and what BDPT renders."""
        w = self.weights
        which = " with a specular vertex" if self.explore == "specular" else ""
        lines = [f"path-space MLT (Veach & Guibas 1997): {self.chains} chains over paths of {self.direct + 1} .. "
                 f"{self.max_depth} segments{which}, started from {self.bootstrap} bootstrap samples (pairs of "
                 f"walks) per length in proportion to the {self.contribution}; mutation weights (each chain chooses "
                 f"among those that can move its path): bidirectional {w[0]:.2f}, lens perturbation {w[1]:.2f}, "
                 f"caustic perturbation {w[2]:.2f}, multi-chain perturbation {w[3]:.2f}; expected-value splatting"]
        if self.explore == "specular":
            short = f"paths of at most {self.direct} segments, and longer ones" if self.direct else "paths"
            lines.append(f"{short} without a specular vertex by BDPT, one sample per pixel per pass")
            if not scene.materials.delta.any():
                lines.append("no specular materials: the chains have no paths to sample, BDPT renders the image")
        elif self.direct:
            lines.append(f"paths of at most {self.direct} segments by BDPT, one sample per pixel per pass")
        return lines

    def check(self, scene) -> None:
        """Path-space MLT needs area lights and a pinhole camera."""
        others = sorted({type(light).__name__ for light in scene.lights.lights if not isinstance(light, AreaLight)})
        if others:
            raise ValueError(f"estimator 'mlt': path-space MLT supports area lights only, the scene has "
                             f"{', '.join(others)}; use 'mmlt' or 'pssmlt'")
        if not scene.camera.delta_position:
            raise ValueError("estimator 'mlt': path-space MLT supports a pinhole camera only, the scene has a thin "
                             "lens; use 'mmlt' or 'pssmlt'")

    def prepare(self, scene) -> None:
        """Build the BVH and load colour-science's matrices before the clock starts."""
        from ..spectra import xyz_to_srgb_matrix

        xyz_to_srgb_matrix()
        scene.accel

    def render(self, job: RenderJob, budget: Budget, on_checkpoint=None) -> None:
        """Bootstrap, then passes of ceil(pixels / chains) steps of every chain plus one BDPT pass of the paths
        the chains leave out, until the budget is spent."""
        film, control = job.film, job.control
        control.deadline = budget.seconds
        pixels = film.pixel_count
        contribution = contribution_function(self.contribution, job.mode)
        stats = job.stats.setdefault("metropolis", {})
        try:
            space = Space(job.scene, job.mode, specular_only=self.explore == "specular")
            boot = self._bootstrap(space, contribution,
                                   lambda key: uniform_stream(job, (_BOOTSTRAP, budget.first_pass) + key),
                                   job.counters, control, job.threads)
        except Interrupted:
            return
        direct = self.direct_estimator if job.scene.lights.count else None
        stats.update(bootstrap=self.bootstrap, brightness=float(boot.brightness.sum()),
                     brightness_standard_error=float(np.sqrt((boot.standard_error ** 2).sum())),
                     brightness_degrees_of_freedom=GROUPS - 1,
                     class_brightness=boot.brightness.tolist(),
                     class_brightness_standard_error=boot.standard_error.tolist(), direct=self.direct)
        per_class = np.bincount(boot.label, minlength=boot.brightness.size)
        groups = []
        if boot.label.size:
            scale = pixels * boot.brightness.take(boot.label) / per_class.take(boot.label)
            groups = [PathChains(space, self, contribution, boot.part(part), scale[part], pixels,
                                 uniform_stream(job, (_CHAINS, budget.first_pass, g)))
                      for g, part in enumerate(split(boot.label.size))]
        steps = -(-pixels // boot.label.size) if groups else 0

        def one_pass(index: int) -> np.ndarray:
            return step_groups(job, groups, steps, self._direct(job, index) if direct is not None else ())

        started = control.elapsed()
        passes = run_passes(job, budget, on_checkpoint, one_pass)
        stats.update(chain_statistics(groups, per_class, passes, steps, control.elapsed() - started))

    def _direct(self, job: RenderJob, pass_index: int) -> list[Callable[[Counters], np.ndarray]]:
        """One BDPT sample per pixel of the paths the chains leave out (those of at most ``direct`` segments, and
        with ``explore='specular'`` the longer ones without a specular vertex), as pieces of the pass: one per range
        of pixels (each with its own random streams), each making an image (3, pixels) with given counters."""
        pixels = job.film.pixel_count

        def render_range(part: slice, counters: Counters) -> np.ndarray:
            samplers = {name: job.samplers.open([(_DIRECT, pass_index, code, part.start)], [part.stop - part.start])
                        for name, code in STREAMS.items()}
            job.control.check()
            found = self.direct_estimator.evaluate(job.scene, np.arange(part.start, part.stop), samplers, job.mode,
                                                   counters)
            return np.stack([np.bincount(found.pixel, weights=found.weighted[c], minlength=pixels)
                             for c in range(job.film.channels)])

        return [partial(render_range, part) for part in split(pixels)]

    def _bootstrap(self, space: Space, contribution, streams, counters: Counters, control: RenderControl,
                   threads: int) -> Bootstrap:
        """b_L with its standard error per path length, and the chains' starts (see the module docstring);
        ``streams(key)``: the random numbers of the reservoirs (key ``()``) and of each batch of walks (``(length,
        batch)``), whose walks are made ``threads`` batches at a time."""
        first = self.direct + 1
        classes = self.max_depth - first + 1
        uniforms = streams(())

        def walk(batch: tuple[int, int, int, Uniforms]) -> tuple[FreshPaths, np.ndarray, int]:
            label, start, count, draw = batch
            control.check()
            fresh = fresh_paths(space, np.full(count, first + label), first + label + 1, draw)
            weighted = fresh.weights()
            c = contribution(weighted)
            finite = np.isfinite(weighted).all(axis=0) & np.isfinite(c)
            return fresh, np.where(finite, c, 0.0), int(finite.size - np.count_nonzero(finite))

        batches = []
        for label in range(classes if space.scene.lights.count else 0):
            size = max(1, BATCH // (first + label + 1))      # pairs of walks; each makes length + 1 paths
            batches += [(label, start, min(size, self.bootstrap - start), streams((label, start // size)))
                        for start in range(0, self.bootstrap, size)]
        sums = np.zeros((classes, GROUPS))
        reservoirs = [{"total": 0.0, "paths": None} for _ in range(classes)]
        for (label, start, _, _), (fresh, c, nonfinite) in in_rounds(threads, walk, batches, control):
            counters.nonfinite_contributions += nonfinite
            sums[label] += np.bincount((start + fresh.pair) % GROUPS, weights=c, minlength=GROUPS)
            _keep(reservoirs[label], c, fresh.paths, self.chains, uniforms)
        picks = [reservoir["paths"] for reservoir in reservoirs]
        per_group = self.bootstrap / GROUPS
        brightness = sums.sum(axis=1) / self.bootstrap
        standard_error = (sums / per_group).std(axis=1, ddof=1) / np.sqrt(GROUPS)
        return self._starts(space, brightness, standard_error, picks)

    def _starts(self, space: Space, brightness, standard_error, picks: list) -> Bootstrap:
        """Share the chains out among the lengths and gather their starting paths."""
        from .paths import evaluate

        per_class = allocate(brightness, self.chains)
        slots = self.max_depth + 1
        paths = Paths.empty(int(per_class.sum()), slots)
        labels, row = [], 0
        for label, count in enumerate(per_class):
            if count:
                chosen = picks[label].take(np.arange(count))
                width = chosen.slots
                paths.k[row:row + count] = chosen.k
                paths.wavelength_number[row:row + count] = chosen.wavelength_number
                for name in Paths.FIELDS:
                    getattr(paths, name)[..., row:row + count, :width] = getattr(chosen, name)
                labels.append(np.full(count, label))
                row += count
        return Bootstrap(brightness, standard_error, paths, evaluate(space, paths) if row else None,
                         np.concatenate(labels) if labels else np.zeros(0, np.int64))


def _keep(reservoir: dict, c: np.ndarray, paths: Paths, slots: int, uniforms) -> None:
    """Weighted reservoir sampling (with replacement) of ``slots`` starting paths in proportion to ``c``."""
    drawn = reservoir_draw(reservoir, c, slots, uniforms)
    if drawn is None:
        return
    candidate, replace = drawn
    chosen = paths.take(candidate)
    held = reservoir["paths"]
    if held is None:
        reservoir["paths"] = chosen
        return
    take = np.flatnonzero(replace)
    held.assign(take, chosen.take(take))
