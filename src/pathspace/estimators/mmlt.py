"""Multiplexed MLT (Hachisuka, Kaplanyan & Dachsbacher 2014; pbrt-v3's MLTIntegrator).

The state of a chain is a path length L (in segments, fixed per chain),
BDPT's numbers (camera subpath, light subpath, wavelengths) and one more
number that picks the strategy (s, t) with s + t - 1 = L uniformly among the
n_L strategies that can make such a path (s = 0 .. L, and s = L + 1 with a
thin lens).  The contribution is the one strategy's MIS-weighted value
times n_L, so its expectation over the strategy number is the sum of all of
them -- BDPT's image of paths of length L -- and small steps of the strategy
number change the strategy (Hachisuka et al., sec. 4).  Chains explore
where each strategy is good: the MIS weight is part of what they sample.

Each path length is a class of chains with its own brightness b_L (see
:mod:`pathspace.estimators.metropolis`): chains are shared out in proportion
to b_L and each length's splats are scaled by its own b_L, so the energy of
each length does not depend on how many chains it received.  Russian
roulette is off (a chain's subpaths have the vertices its length needs).

Parameters
----------
max_depth : int, default 16
    Longest path in segments (path lengths 1 .. max_depth; a finite bound
    is required: each length has its chains).
mis, mis_beta : "power" (default), "balance", "uniform"; 2
    The MIS heuristic among the strategies of a length.
chains, bootstrap, p_large, small_step, step_size, contribution
    See :class:`pathspace.estimators.metropolis.Metropolis`; ``bootstrap``
    samples are taken per path length.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import numpy as np

from ..checks import choice, integer
from . import parameters as p
from .base import Counters, parameter
from .bdpt import BDPT
from .metropolis import Metropolis, Proposal, Target
from .pssmlt import first_pixels

__all__ = ["MMLT"]

HEURISTICS = ("power", "balance", "uniform")


class StrategyTarget(Target):
    """One strategy of one path length, chosen by the chain's strategy number, times the number of strategies."""

    streams = ("camera", "light", "wavelengths", "strategy")

    def __init__(self, estimator: BDPT, scene, mode) -> None:
        self.estimator, self.scene, self.mode = estimator, scene, mode
        self.film = (scene.camera.width, scene.camera.height)
        self.classes = estimator.max_depth
        self.lens = not scene.camera.delta_position   # a thin lens: the light subpath may reach it (t = 0)

    def strategies(self, length: np.ndarray) -> np.ndarray:
        """n_L: the strategies that make paths of ``length`` segments (s = 0 .. L, and L + 1 with a lens)."""
        return length + 1 + int(self.lens)

    def evaluate(self, states, rows, labels, counters: Counters) -> Proposal:
        """The chosen strategy's weighted value, times the number of strategies."""
        length = labels + 1
        count = self.strategies(length)
        u = states["strategy"].fetch(rows, np.zeros(rows.size, np.int64))
        s = np.minimum((u * count).astype(np.int64), count - 1)
        pixels = first_pixels(states["camera"], rows, self.film)
        samplers = {name: states[name].sampler(rows, self.film if name == "camera" else None)
                    for name in ("camera", "light", "wavelengths")}
        found = self.estimator.evaluate(self.scene, pixels, samplers, self.mode, counters, (s, length + 1 - s))
        keep = np.flatnonzero(found.weighted.any(axis=0))
        return Proposal(found.lane.take(keep), found.pixel.take(keep),
                        found.weighted.take(keep, axis=1) * count.take(found.lane.take(keep)))


@dataclass
class MMLT(Metropolis):
    """Multiplexed MLT; see the module docstring for the parameters."""

    name = "mmlt"

    max_depth: int = parameter(16, "longest path in segments (each length 1 .. max_depth has its own chains)",
                               partial(integer, low=1))
    mis: str = parameter("power", "MIS heuristic among a length's strategies: 'power', 'balance' or 'uniform'",
                         lambda value, name: choice(value, name, HEURISTICS))
    mis_beta: float = p.mis_beta()
    kernel: str = p.kernel("BDPT's vertices and connections")
    inner: BDPT = field(init=False, repr=False)

    def __post_init__(self) -> None:
        super().__post_init__()
        self.inner = BDPT(max_depth=self.max_depth, rr="off", mis=self.mis, mis_beta=self.mis_beta,
                          kernel=self.kernel)

    def plan(self, scene) -> list[str]:
        """The strategies the chains choose from, then the Metropolis settings."""
        return ([f"multiplexed MLT: one chain class per path length 1 .. {self.max_depth}; a chain samples one "
                 f"BDPT strategy (s, t) of its length at a time, weighted by the {self.mis} heuristic times the "
                 "number of strategies; no Russian roulette"] + super().plan(scene))

    def check(self, scene) -> None:
        """BDPT's checks."""
        self.inner.check(scene)

    def prepare(self, scene) -> None:
        """What BDPT builds, and the Metropolis set-up."""
        super().prepare(scene)
        self.inner.prepare(scene)

    def target(self, scene, mode) -> Target:
        """One strategy of one length per chain."""
        return StrategyTarget(self.inner, scene, mode)
