"""The bootstrap of a Metropolis render: the image brightness b, and the chains' starting states.

Veach (1997, sec. 11.3.1): b = E[f(x)] over uniform numbers x, estimated from
independent samples, normalises the image; starting each chain at one of
those samples drawn in proportion to f (resampling) removes start-up bias
without burn-in.  Per class of chains (MMLT's path lengths) the bootstrap
takes ``samples`` samples, estimates b_c with its standard error, and keeps
a sample per chain slot by weighted reservoir sampling (with replacement),
so the samples need not be stored.

Stratification (:class:`Strata`).  For a film target the samples come in
rounds of one per pixel, and the complete rounds are dealt into
``GROUPS`` independent groups; within a group, a pixel's successive samples
visit the cells of a K x K grid over the pixel in turn (from a random cell
per pixel and group), each jittered.  Every sample is still uniform over the
film, so b is unbiased, but the variance between pixels (the light's few
bright pixels) and most within them (the light's edge) is gone.  The
standard error is that of the group means (independent replicates).  Samples
of a last, incomplete round lie in random distinct pixels with uniform
jitter.
"""
from __future__ import annotations

from dataclasses import dataclass
from math import isqrt
from typing import Callable

import numpy as np

from .base import Counters, counted
from .control import RenderControl
from .primary import ChainStates, Uniforms
from .workers import in_rounds

__all__ = ["BATCH", "GROUPS", "BootstrapResult", "Strata", "allocate", "bootstrap", "reservoir_draw"]

BATCH = 1 << 14   # bootstrap samples evaluated together
GROUPS = 8        # independent replicates for the standard error


@dataclass
class BootstrapResult:
    """Per class: ``brightness`` b_c (mean f), its ``standard_error`` (with ``degrees_of_freedom``: the error
    comes from that many + 1 group means, so confidence intervals take Student's t quantiles), ``samples``;
    and the start ``numbers`` (per stream, (chains, dims)) and ``label`` of the chains, drawn per class in
    proportion to f."""

    brightness: np.ndarray
    standard_error: np.ndarray
    samples: int
    numbers: dict[str, np.ndarray]
    label: np.ndarray
    degrees_of_freedom: int


class Strata:
    """Where bootstrap sample i lies: its pixel, its position in the pixel, and its group (see the module
    docstring); without a film, sample i is in group i mod GROUPS."""

    def __init__(self, film: tuple[int, int] | None, samples: int, uniforms: Callable[[int], np.ndarray]) -> None:
        self.film = film
        self.pixels = film[0] * film[1] if film is not None else 1
        self.rounds = samples // self.pixels                   # complete rounds
        self.groups = min(GROUPS, self.rounds)
        self.cells = isqrt(self.rounds // self.groups) if self.groups else 1
        self.offset = (uniforms(self.groups * self.pixels) * self.cells ** 2).astype(np.int64).reshape(
            self.groups, self.pixels) if self.groups else None
        self.tail = np.argsort(uniforms(self.pixels)) if film is not None else None

    def place(self, index: np.ndarray, uniforms) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """(pixel (n,), film numbers (2, n) or None without a film, group (n,); -1: the incomplete round)."""
        r = index // self.pixels
        complete = r < self.rounds
        group = np.where(complete, r % max(self.groups, 1), -1)
        if self.film is None:
            return np.zeros(index.size, np.int64), None, group
        within = index % self.pixels
        pixel = np.where(complete, within, self.tail.take(within))
        cell = np.zeros(index.size, np.int64)
        k = np.flatnonzero(complete)
        if k.size:
            cell[k] = (r.take(k) // self.groups + self.offset[group.take(k), pixel.take(k)]) % self.cells ** 2
        jitter = uniforms(2 * index.size).reshape(2, -1)
        size = np.where(complete, 1.0 / self.cells, 1.0)
        x = (cell % self.cells + jitter[0]) * size
        y = (cell // self.cells + jitter[1]) * size
        width, height = self.film
        return pixel, np.stack([(pixel % width + x) / width, (pixel // width + y) / height]), group


def bootstrap(target, samples: int, chains: int, contribution, streams: Callable[[tuple], Uniforms],
              counters: Counters, control: RenderControl | None = None, threads: int = 1) -> BootstrapResult:
    """Estimate every class's brightness from ``samples`` independent samples per class and draw the chains'
    starts (see the module docstring).  ``streams(key)`` supplies the random numbers: ``()`` those of the strata
    and the reservoirs, ``(class, batch)`` those of one batch of samples; batches are evaluated ``threads`` at a
    time (the result does not depend on ``threads``), checking ``control`` (the render's brakes) before each."""
    from .metropolis import evaluate_target

    uniforms = streams(())
    strata = [Strata(target.film, samples, uniforms) for _ in range(target.classes)]
    batch_starts = [(label, start) for label in range(target.classes) for start in range(0, samples, BATCH)]
    # One set of fresh states per batch of a round of in_rounds (`threads` consecutive batches), reused from round
    # to round: cleared, they cost what a batch draws, where new ones would grow to its width anew.
    workspaces = [{name: ChainStates(BATCH, None, uniforms, fresh=True) for name in target.streams}
                  for _ in range(min(max(threads, 1), len(batch_starts)))]

    def evaluate(batch: tuple[Counters, int, int, Uniforms, dict[str, ChainStates]]) -> tuple[np.ndarray, np.ndarray]:
        own, label, start, draw, states = batch
        if control is not None:
            control.check()
        index = np.arange(start, min(start + BATCH, samples))
        for s in states.values():
            s.uniforms = draw
        _, film, group = strata[label].place(index, draw)
        if film is not None:
            first = states[target.streams[0]]
            first.set_proposal(0, film[0])
            first.set_proposal(1, film[1])
        _, f = evaluate_target(target, states, np.full(index.size, label), contribution, own)
        return f, group

    sums = np.zeros((target.classes, GROUPS + 1))      # per class and group (the last: the incomplete round)
    counts = np.zeros(GROUPS + 1)
    squares = np.zeros(target.classes)
    picks: list[dict] = [{"total": 0.0, "numbers": {}} for _ in range(target.classes)]
    with counted(counters, len(batch_starts)) as own:   # what an interrupted bootstrap traced counts too
        batches = [(own[k], label, start, streams((label, start // BATCH)), workspaces[k % len(workspaces)])
                   for k, (label, start) in enumerate(batch_starts)]
        for (_, label, _, _, states), (f, group) in in_rounds(threads, evaluate, batches, control):
            slot = np.where(group < 0, GROUPS, group)
            sums[label] += np.bincount(slot, weights=f, minlength=GROUPS + 1)
            if label == 0:   # every class has the same strata
                counts += np.bincount(slot, minlength=GROUPS + 1)
            squares[label] += (f * f).sum()
            _reservoir(picks[label], f, states, chains, uniforms)
            for s in states.values():
                s.clear()
    brightness = sums.sum(axis=1) / samples
    groups = np.flatnonzero(counts[:GROUPS] > 0)
    if groups.size >= 2:
        means = sums[:, groups] / counts[groups]
        standard_error = means.std(axis=1, ddof=1) / np.sqrt(groups.size)
        dof = int(groups.size) - 1
    else:   # a single (partial) round: the spread of all samples, which overestimates a stratified error
        variance = np.maximum(squares / samples - brightness ** 2, 0.0) * samples / max(samples - 1, 1)
        standard_error = np.sqrt(variance / samples)
        dof = max(samples - 1, 1)
    result = _starts(target, picks, brightness, standard_error, samples, chains)
    result.degrees_of_freedom = dof
    return result


def _starts(target, picks: list[dict], brightness, standard_error, samples: int, chains: int) -> BootstrapResult:
    """Share the chains out among the classes and stack their starting numbers (``degrees_of_freedom`` is
    left for the caller)."""
    per_class = allocate(brightness, chains)
    numbers: dict[str, list[np.ndarray]] = {name: [] for name in target.streams}
    labels = []
    for label, count in enumerate(per_class):
        if count:
            for name in target.streams:
                numbers[name].append(picks[label]["numbers"][name][:count])
            labels.append(np.full(count, label))
    width = {name: max((a.shape[1] for a in parts), default=0) for name, parts in numbers.items()}
    stacked = {name: np.concatenate([np.pad(a, ((0, 0), (0, width[name] - a.shape[1])), constant_values=np.nan)
                                     for a in parts]) if parts else np.zeros((0, 0))
               for name, parts in numbers.items()}
    return BootstrapResult(brightness, standard_error, samples, stacked,
                           np.concatenate(labels) if labels else np.zeros(0, np.int64), 0)


def reservoir_draw(reservoir: dict, f: np.ndarray, slots: int, uniforms) -> tuple[np.ndarray, np.ndarray] | None:
    """One batch of weighted reservoir sampling with replacement: each of ``slots`` slots holds one sample drawn
    with probability proportional to f among all the samples seen so far.  Returns each slot's candidate in this
    batch (drawn in proportion to ``f``) and whether it replaces the slot's sample (with probability batch total
    / running total ``reservoir["total"]``, updated here), or None if the batch weighs nothing."""
    total = float(f.sum())
    if total <= 0.0:
        return None
    reservoir["total"] += total
    u = uniforms(2 * slots).reshape(2, slots)
    cdf = np.cumsum(f)
    candidate = np.minimum(np.searchsorted(cdf, u[0] * cdf[-1], side="right"), f.size - 1)
    return candidate, u[1] < total / reservoir["total"]


def _reservoir(reservoir: dict, f: np.ndarray, states: dict[str, ChainStates], slots: int, uniforms) -> None:
    """:func:`reservoir_draw` of the numbers of chain states ``states`` (only the replaced slots are copied)."""
    drawn = reservoir_draw(reservoir, f, slots, uniforms)
    if drawn is None:
        return
    candidate, replace = drawn
    rows = np.flatnonzero(replace)
    for name, s in states.items():
        chosen = s.numbers(candidate.take(rows), proposal=True)
        held = reservoir["numbers"].get(name)
        if held is None:     # the first batch with weight replaces every slot (its share of the total is 1)
            reservoir["numbers"][name] = chosen
            continue
        if held.shape[1] < chosen.shape[1]:
            held = np.pad(held, ((0, 0), (0, chosen.shape[1] - held.shape[1])), constant_values=np.nan)
            reservoir["numbers"][name] = held
        held[rows, :chosen.shape[1]] = chosen
        held[rows, chosen.shape[1]:] = np.nan


def allocate(brightness: np.ndarray, chains: int) -> np.ndarray:
    """Chains per class: proportional to the brightness (largest remainders), at least one per bright class."""
    bright = brightness > 0
    if not bright.any():
        return np.zeros(brightness.size, np.int64)
    share = np.where(bright, brightness, 0.0) / brightness[bright].sum() * chains
    count = np.maximum(np.floor(share).astype(np.int64), bright.astype(np.int64))
    while count.sum() < chains:
        count[np.argmax(np.where(bright, share - count, -np.inf))] += 1
    while count.sum() > chains and (count > 1).any():
        count[np.argmax(np.where(count > 1, count - share, -np.inf))] -= 1
    return count
