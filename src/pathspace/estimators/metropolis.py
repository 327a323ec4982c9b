"""Metropolis light transport over primary sample space: the chains, their normalisation and splatting.

What every primary-sample-space Metropolis estimator (PSSMLT, MMLT) shares;
what differs is the :class:`Target` -- how a chain's numbers become film
contributions (a path tracer's sample, every BDPT strategy of a sample, one
strategy of one path length).

The image (Veach 1997, sec. 11.3; Kelemen et al. 2002)
-------------------------------------------------------
A target maps numbers x to film contributions V_k(x) at pixels j_k(x); with
uniform x, the sum of a sample's contributions landing on pixel j estimates
I_j / P (P pixels), as one pixel sample of a pass does.  The scalar
contribution f(x) = sum_k c(V_k(x)) (c: luminance Y by default) is the
density the chains sample, up to its integral b = E[f(x)].  Then

    I_j = P b E_{x ~ f/b}[ sum_k V_k(x) [j_k(x) = j] / f(x) ],

so every mutation splats V_k / f times P b / (mutations).  Targets may
split their numbers into *classes* with separate chains (MMLT: one per path
length); each class c has its own brightness b_c and its chains' splats are
scaled by P b_c / (its mutations), so the share of chains a class receives
changes only the noise, never the brightness (pbrt-v3 weighs every class by
the shared b instead, and the energy of each path length then moves with
the random number of chains it got).

Normalisation and start (Veach 1997, sec. 11.3.1; :mod:`pathspace.estimators.bootstrap`)
-----------------------------------------------------------------------------------------
``bootstrap`` independent samples per class (stratified over the film)
estimate b_c, reported with its standard error; each class receives chains
in proportion to b_c (at least one where b_c > 0), and every chain starts at
a bootstrap sample drawn with probability proportional to f (resampling), so
it starts in (approximately) the stationary distribution: no burn-in.

Mutations and splatting
-----------------------
Each step, every chain proposes a large step (probability ``p_large``)
or a small step of all its numbers (:mod:`pathspace.estimators.primary`),
accepts with a = min(1, f(y) / f(x)), and splats the proposal with weight a
and the current state with weight 1 - a (expected values; Veach 1997,
sec. 11.4.2).  A pass is ceil(P / chains) steps of every chain (at least one
mutation per pixel; one step of every chain when there are more chains than
pixels), so a render of ``spp`` passes makes at least spp x P mutations; each
pass's splats form one image estimate on the film.  The chains step in groups of
at most :data:`~pathspace.estimators.workers.PIECE`, each with its own random
stream, on the render's threads (and the bootstrap evaluates its batches so):
the groups depend on the number of chains alone, so the image does not depend
on the thread count.  Renders of disjoint pass
ranges (``first_pass``) run their own bootstrap and chains.  Passes
of the same chains are correlated, so the film's per-pixel variance
underestimates the error: estimate it from independent renders (seeds).
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import partial
from typing import Callable, ClassVar, Sequence

import numpy as np

from ..checks import choice, integer, number
from .base import Budget, Checkpoint, Counters, Estimator, RenderJob, counted, parameter
from .bootstrap import bootstrap
from .control import Interrupted
from .primary import KERNELS, ChainStates, SmallStep, advance, new_counters
from .workers import in_order, in_parallel, split

__all__ = ["CHAINS", "CONTRIBUTIONS", "Metropolis", "Proposal", "Target", "Chains", "Splatting", "chain_statistics",
           "contribution_function", "evaluate_target", "run_passes", "step_groups", "uniform_stream"]

CONTRIBUTIONS = ("luminance", "xyz", "max")
# Default number of chains (PSSMLT, MMLT and path-space MLT).  Fewer, longer chains keep less of the error of
# where they started.  At 30 s on the 128 x 128 ajar-door and caustic-glass scenes, 8192 chains gave lower relMSE
# than 16384:
# - PSSMLT over PT: 1.4-1.8x lower;
# - MMLT: 1.1-1.2x lower;
# - path-space MLT: 1.2-1.5x lower on the ajar door, 7% higher on the caustic scene.
# 4096 chains were no better.  65536 chains doubled the mutations per second on two threads, yet gave 1.3-2.3x
# higher relMSE (path-space MLT on the caustic scene: the same; README, "Chain count").
CHAINS = 8192
# Random streams of a render (the first number of each unit key); then the first pass, and the class and batch
# (bootstrap) or the group (chains).
_BOOTSTRAP, _CHAINS = 0, 1


@dataclass
class Proposal:
    """Film contributions of evaluated numbers: ``value`` (C, k) film values landing on ``pixel`` (k,), made by
    evaluated lane ``lane`` (k,) (lanes with no contribution have none)."""

    lane: np.ndarray
    pixel: np.ndarray
    value: np.ndarray


class Target(ABC):
    """How numbers become film contributions, for a Metropolis estimator on one scene and colour mode."""

    streams: ClassVar[tuple[str, ...]]   # the random streams a state holds, by name
    classes: int = 1                     # classes of chains (e.g. path lengths), normalised separately
    film: tuple[int, int] | None = None  # (width, height) if the first two numbers of streams[0] place the
                                         # sample on the film: the bootstrap then stratifies them by pixel

    @abstractmethod
    def evaluate(self, states: dict[str, ChainStates], rows: np.ndarray, labels: np.ndarray,
                 counters: Counters) -> Proposal:
        """The contributions of the proposals of chains ``rows`` (of classes ``labels``); the lanes of the
        result index ``rows``."""


def contribution_function(kind: str, mode) -> Callable[[np.ndarray], np.ndarray]:
    """The scalar contribution c of film values (C, k): |Y| (``"luminance"``), |X + Y + Z| (``"xyz"``), or
    the largest |film channel| (``"max"``: of linear sRGB, or of XYZ for spectral renders)."""
    if kind == "max":
        return lambda values: np.abs(values).max(axis=0)
    if mode.film_to_srgb is None:        # the film holds linear sRGB
        from ..spectra import xyz_to_srgb_matrix

        to_xyz = np.linalg.inv(xyz_to_srgb_matrix())
    else:                                # the film holds XYZ
        to_xyz = np.eye(3)
    row = to_xyz[1] if kind == "luminance" else to_xyz.sum(axis=0)
    return lambda values: np.abs(row @ values)


def evaluate_target(target: Target, states: dict[str, ChainStates], label: np.ndarray,
                    contribution: Callable[[np.ndarray], np.ndarray],
                    counters: Counters) -> tuple[Proposal, np.ndarray]:
    """The contributions of the proposals of chains 0 .. ``label.size`` - 1 (of classes ``label``) in ``states``,
    and their scalar contributions f (per chain); contributions with a NaN or Inf are dropped and counted."""
    proposal = target.evaluate(states, np.arange(label.size), label, counters)
    scalar = contribution(proposal.value)
    finite = np.isfinite(proposal.value).all(axis=0) & np.isfinite(scalar)
    if not finite.all():
        counters.nonfinite_contributions += int(finite.size - np.count_nonzero(finite))
        keep = np.flatnonzero(finite)
        proposal = Proposal(proposal.lane.take(keep), proposal.pixel.take(keep), proposal.value.take(keep, axis=1))
        scalar = scalar.take(keep)
    return proposal, np.bincount(proposal.lane, weights=scalar, minlength=label.size)


class Splatting:
    """Expected-value splatting and the statistics of a wavefront of Markov chains (Veach 1997, sec. 11.4.2).

    Each step splats a chain's proposal with weight a and adds 1 - a to the ``pending`` weight of its current
    state, which reaches the film when the chain moves on (:meth:`flush`).  ``scale[i]``: what chain i's
    splats of one step are multiplied by; ``f`` (chains,): the scalar contribution of the current states;
    ``current``: their film contributions.
    """

    def __init__(self, scale: np.ndarray, pixels: int, channels: int, kinds: tuple[str, ...]) -> None:
        n = scale.size
        self.scale, self.pixels, self.channels = scale, pixels, channels
        self.f = np.zeros(n)
        self.pending = np.zeros(n)          # the current state's splat weight not yet on the film
        self.current = Proposal(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((channels, 0)))
        self.rejections = np.zeros(n, np.int64)
        self.longest_rejections = np.zeros(n, np.int64)
        self.proposed = {kind: 0 for kind in kinds}
        self.accepted = {kind: 0 for kind in kinds}

    def propose(self, image: np.ndarray, proposal: Proposal, f_new: np.ndarray, accept_p: np.ndarray) -> None:
        """Splat ``proposal`` (scalar contributions ``f_new`` per chain) with weight ``accept_p`` and keep the
        rest pending on the current states."""
        with np.errstate(divide="ignore", invalid="ignore"):
            weight = np.where(f_new > 0, accept_p * self.scale / f_new, 0.0)
        self._splat(image, proposal, weight)
        self.pending += 1.0 - accept_p

    def settle(self, image: np.ndarray, accept: np.ndarray, kind: np.ndarray, kinds: tuple[str, ...]) -> None:
        """Flush the chains that ``accept`` and note the step's statistics; ``kind`` (chains,) indexes ``kinds``."""
        self.flush(image, accept)
        self.rejections = np.where(accept, 0, self.rejections + 1)
        np.maximum(self.longest_rejections, self.rejections, out=self.longest_rejections)
        for code, name in enumerate(kinds):
            mask = kind == code
            self.proposed[name] += int(mask.sum())
            self.accepted[name] += int((mask & accept).sum())

    def flush(self, image: np.ndarray, chains: np.ndarray | None = None) -> None:
        """Splat the pending weight of the current states of ``chains`` (bool per chain; None: all)."""
        pending = self.pending if chains is None else np.where(chains, self.pending, 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            weight = np.where(self.f > 0, pending * self.scale / self.f, 0.0)
        self._splat(image, self.current, weight)
        if chains is None:
            self.pending[:] = 0.0
        else:
            self.pending[chains] = 0.0

    def _splat(self, image: np.ndarray, contributions: Proposal, weight: np.ndarray) -> None:
        w = weight.take(contributions.lane)
        live = np.flatnonzero(w)
        if not live.size:
            return
        pixel = contributions.pixel.take(live)
        for c in range(self.channels):
            image[c] += np.bincount(pixel, weights=contributions.value[c].take(live) * w.take(live),
                                    minlength=self.pixels)


STEPS = ("small", "large")


class Chains(Splatting):
    """Metropolis chains over a target's streams, with their current contributions and statistics."""

    def __init__(self, target: Target, contribution: Callable[[np.ndarray], np.ndarray], step: SmallStep,
                 p_large: float, uniforms: Callable[[int], np.ndarray], label: np.ndarray, scale: np.ndarray,
                 pixels: int, channels: int) -> None:
        super().__init__(scale, pixels, channels, STEPS)
        self.target, self.contribution, self.step, self.p_large = target, contribution, step, p_large
        self.uniforms, self.label = uniforms, label
        n = label.size
        self.counters = new_counters(n)
        self.states = {name: ChainStates(n, step, uniforms, self.counters) for name in target.streams}

    def start(self, numbers: dict[str, np.ndarray], counters: Counters) -> None:
        """Start every chain at the given numbers (per stream, (chains, dims), NaN: not drawn) and evaluate them."""
        rows = np.arange(self.label.size)
        for name, states in self.states.items():
            states.load(rows, numbers[name])
        for states in self.states.values():
            states.replay = True
        self.current, self.f = self._evaluate(counters)
        for states in self.states.values():   # the current state keeps what the evaluation drew
            states.replay = False
            states.settle(np.zeros(rows.size, bool))

    def _evaluate(self, counters: Counters) -> tuple[Proposal, np.ndarray]:
        """The proposals' contributions and f (see :func:`evaluate_target`)."""
        return evaluate_target(self.target, self.states, self.label, self.contribution, counters)

    def step_all(self, image: np.ndarray, counters: Counters) -> None:
        """One mutation of every chain, splatting into ``image`` (C, pixels)."""
        n = self.label.size
        u = self.uniforms(2 * n).reshape(2, n)
        large = u[0] < self.p_large
        self.counters["large"][:] = large
        proposal, f_new = self._evaluate(counters)
        with np.errstate(divide="ignore", invalid="ignore"):
            accept_p = np.where(self.f > 0, np.minimum(1.0, f_new / self.f), 1.0)
        self.propose(image, proposal, f_new, accept_p)
        accept = u[1] < accept_p
        self.settle(image, accept, large.astype(np.int64), STEPS)
        kept = ~accept.take(self.current.lane)
        taken = accept.take(proposal.lane)
        self.current = Proposal(*(np.concatenate([np.compress(kept, getattr(self.current, name), axis=-1),
                                                  np.compress(taken, getattr(proposal, name), axis=-1)], axis=-1)
                                  for name in ("lane", "pixel", "value")))
        self.f = np.where(accept, f_new, self.f)
        for states in self.states.values():
            states.settle(accept)
        advance(self.counters, accept)


def _positive_integer(value, name):
    return integer(value, name, low=1)


@dataclass
class Metropolis(Estimator):
    """Base of the primary-sample-space Metropolis estimators (see the module docstring for the method)."""

    independent_passes = False

    chains: int = parameter(CHAINS, "Markov chains, stepped in groups of at most 16384 (one wavefront each) on the "
                                    "render's threads", _positive_integer)
    bootstrap: int = parameter(1 << 16, "independent samples per chain class that estimate the image brightness "
                                        "and the chains' starting states", _positive_integer)
    p_large: float = parameter(0.3, "probability of a large step (fresh numbers) per mutation",
                               partial(number, low=0.0, high=1.0, what="a probability in [0, 1]"))
    small_step: str = parameter("exponential", "small-step kernel: 'exponential' (Kelemen et al. 2002) or "
                                               "'gaussian' (pbrt-v3)", partial(choice, options=KERNELS))
    step_size: float = parameter(1.0 / 64.0, "small-step size: s2 of the exponential kernel (s1 = s2 / 16), the "
                                             "standard deviation of the Gaussian",
                                 partial(number, low=0.0, high=0.25, low_open=True, what="a number in (0, 0.25]"))
    contribution: str = parameter("luminance", "the scalar the chains sample: 'luminance' (Y), 'xyz' (X + Y + Z) "
                                               "or 'max' (largest channel)", partial(choice, options=CONTRIBUTIONS))

    def prepare(self, scene) -> None:
        """Build the BVH and load colour-science's matrices (the luminance of RGB films) before the clock starts."""
        from ..spectra import xyz_to_srgb_matrix

        xyz_to_srgb_matrix()
        scene.accel

    @abstractmethod
    def target(self, scene, mode) -> Target:
        """The target of a render of ``scene`` in colour ``mode``."""

    def plan(self, scene) -> list[str]:
        """The Metropolis settings (subclasses add what the target does)."""
        return [f"{self.chains} chains started from {self.bootstrap} bootstrap samples per class in proportion to "
                f"the {self.contribution}; small steps: {self.small_step} of size {self.step_size:g}; large steps "
                f"with probability {self.p_large:g}; expected-value splatting"]

    def render(self, job: RenderJob, budget: Budget,
               on_checkpoint: Callable[[Checkpoint], None] | None = None) -> None:
        """Bootstrap, then passes of ceil(pixels / chains) steps of every chain until the budget is spent."""
        film, control = job.film, job.control
        control.deadline = budget.seconds
        pixels = film.pixel_count
        target = self.target(job.scene, job.mode)
        contribution = contribution_function(self.contribution, job.mode)
        step = SmallStep(self.small_step, self.step_size)
        stats = job.stats.setdefault("metropolis", {})
        try:
            boot = bootstrap(target, self.bootstrap, self.chains, contribution,
                             lambda key: uniform_stream(job, (_BOOTSTRAP, budget.first_pass) + key),
                             job.counters, control, job.threads)
        except Interrupted:
            return
        stats.update(bootstrap=boot.samples, brightness=float(boot.brightness.sum()),
                     brightness_standard_error=float(np.sqrt((boot.standard_error ** 2).sum())),
                     brightness_degrees_of_freedom=boot.degrees_of_freedom,
                     class_brightness=boot.brightness.tolist(),
                     class_brightness_standard_error=boot.standard_error.tolist())
        if not boot.label.size:
            self._black_passes(job, budget)
            return
        per_class = np.bincount(boot.label, minlength=target.classes)
        scale = pixels * boot.brightness.take(boot.label) / per_class.take(boot.label)
        parts = split(boot.label.size)
        groups = [Chains(target, contribution, step, self.p_large, uniform_stream(job, (_CHAINS, budget.first_pass, g)),
                         boot.label[part], scale[part], pixels, film.channels) for g, part in enumerate(parts)]

        with counted(job.counters, len(groups)) as counters:
            def start(g: int) -> None:
                groups[g].start({name: numbers[parts[g]] for name, numbers in boot.numbers.items()}, counters[g])

            in_parallel(job.threads, start, range(len(groups)), control)
        steps = -(-pixels // boot.label.size)
        started = control.elapsed()
        passes = run_passes(job, budget, on_checkpoint, lambda _: step_groups(job, groups, steps))
        stats.update(chain_statistics(groups, per_class, passes, steps, control.elapsed() - started))

    def _black_passes(self, job: RenderJob, budget: Budget) -> None:
        """Nothing contributes (the bootstrap found no light): the budget's passes are black."""
        passes = budget.spp if budget.spp is not None else 1
        for k in range(passes):
            job.film.add_samples(budget.first_pass + k, 0, np.zeros((job.film.channels, job.film.pixel_count)))


def run_passes(job: RenderJob, budget: Budget, on_checkpoint: Callable[[Checkpoint], None] | None,
               one_pass: Callable[[int], np.ndarray]) -> int:
    """Put the images ``one_pass(pass index)`` (C, pixels) on the film as passes until the budget is spent or
    the render is interrupted, firing checkpoints and progress; returns the passes made."""
    from .passes import _Checkpoints

    checkpoints = _Checkpoints(budget, job, on_checkpoint)
    passes = 0
    try:
        while budget.spp is None or passes < budget.spp:
            job.control.check()
            index = budget.first_pass + passes
            job.film.add_samples(index, 0, one_pass(index))
            passes += 1
            if job.progress is not None:
                job.progress.update(1)
            checkpoints.update()
    except Interrupted:
        pass
    return passes


def step_groups(job: RenderJob, groups: Sequence[Splatting], steps: int,
                others: Sequence[Callable[[Counters], np.ndarray]] = ()) -> np.ndarray:
    """One pass of independent groups of chains (each with a ``step_all``): ``steps`` steps of every chain, then
    the splats still pending; the pass's image (C, pixels), summed over the groups in their order and divided by
    ``steps``.  ``others``: more pieces of the pass (images made with the given counters, e.g. path-space MLT's
    BDPT pass of the direct paths), added in their order.  All pieces, groups first, run on the render's threads
    as the threads come free (:func:`~pathspace.estimators.workers.in_order`): a pass of one group of chains and
    one range of direct pixels keeps two threads busy.  Up to twice the threads' images are held at once (finished
    pieces wait for the one before them), so that the other threads can render several ranges of direct pixels
    while one steps the chains.  What the pieces count joins ``job.counters``, also when the render is
    interrupted."""
    def walk(g: int, counters: Counters) -> np.ndarray:
        image = np.zeros((job.film.channels, job.film.pixel_count))
        for _ in range(steps):
            job.control.check()
            groups[g].step_all(image, counters)
        groups[g].flush(image)
        return image

    pieces = [partial(walk, g) for g in range(len(groups))] + list(others)
    chained = np.zeros((job.film.channels, job.film.pixel_count))
    other = np.zeros_like(chained)
    with counted(job.counters, len(pieces)) as counters:
        for k, part in in_order(job.threads, lambda k: pieces[k](counters[k]), range(len(pieces)), job.control):
            if k < len(groups):
                chained += part
            else:
                other += part
    return chained / steps + other if groups else other


def chain_statistics(groups: Sequence[Splatting], per_class: np.ndarray, passes: int, steps: int,
                     seconds: float) -> dict:
    """What a Metropolis render reports of its ``groups`` of chains after ``passes`` of ``steps`` steps in
    ``seconds`` (see ``docs/metropolis.md``); ``per_class``: chains per class."""
    count = int(per_class.sum())
    mutations = passes * steps * count
    found = dict(chains=count, chains_per_class=per_class.tolist(), steps_per_pass=steps, mutations=mutations,
                 mutations_per_second=mutations / seconds if seconds > 0 else 0.0)
    if groups:
        proposed = {kind: sum(g.proposed[kind] for g in groups) for kind in groups[0].proposed}
        accepted = {kind: sum(g.accepted[kind] for g in groups) for kind in groups[0].accepted}
        longest = np.concatenate([g.longest_rejections for g in groups])
        total = sum(proposed.values())
        found.update(acceptance={k: accepted[k] / proposed[k] if proposed[k] else None for k in proposed},
                     proposal_share={k: proposed[k] / total if total else 0.0 for k in proposed},
                     longest_rejection_run=int(longest.max()),
                     longest_rejection_run_median=float(np.median(longest)))
    return found


def uniform_stream(job: RenderJob, key: tuple[int, ...]) -> Callable[[int], np.ndarray]:
    """k -> k uniform numbers from the render's sampler source, unit ``key`` (one lane drawing them all)."""
    sampler = job.samplers.open([key], [1])
    return lambda k: sampler.draw(k)[:, 0]
