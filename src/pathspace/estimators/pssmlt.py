"""Primary-sample-space MLT (Kelemen, Szirmay-Kalos, Antal & Csonka 2002) over the path tracer or BDPT.

A chain's state is the numbers one sample of the underlying estimator
draws (:mod:`pathspace.estimators.primary`): for ``over="pt"`` the path
tracer's (film position, lens, wavelengths, then per vertex light, BSDF and
roulette numbers: :meth:`PathTracer.dimensions`); for ``over="bdpt"`` BDPT's
three streams (camera subpath, light subpath, wavelengths), all of whose
(s, t) strategies, weighted by MIS, make the sample's contributions.  The
first two camera numbers place the sample anywhere on the film, so small
steps move it to nearby pixels (Kelemen et al., sec. 4).  The chains, their
normalisation and splatting are :mod:`pathspace.estimators.metropolis`.

Parameters
----------
over : "pt" (default) or "bdpt"
    The estimator whose samples the chains explore.
max_depth : int, default 16
    Longest path in segments.  It must be finite: a chain's state holds
    every number its path draws (chains x numbers, dense), and every step
    waits for the longest path of the wavefront (a ray trapped by total
    internal reflection in glass would otherwise hold up all the chains).
    Compare with other estimators at the same ``max_depth``.
rr, rr_depth
    The underlying estimator's roulette (default: its own defaults); its
    other parameters keep their defaults.
chains, bootstrap, p_large, small_step, step_size, contribution
    See :class:`pathspace.estimators.metropolis.Metropolis`.
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
from .primary import ChainStates, film_position
from .pt import PathTracer

__all__ = ["PSSMLT"]

OVER = ("pt", "bdpt")


def first_pixels(states: ChainStates, rows: np.ndarray, film: tuple[int, int]) -> np.ndarray:
    """The pixels the proposals of chains ``rows`` start in (their first two numbers, over the whole film)."""
    u = states.fetch(np.repeat(rows, 2), np.tile(np.arange(2), rows.size)).reshape(-1, 2).T
    return film_position(u, film)


class PathTarget(Target):
    """A path tracer's sample: one contribution, at the pixel it starts in."""

    streams = ("camera",)

    def __init__(self, estimator: PathTracer, scene, mode) -> None:
        self.estimator, self.scene, self.mode = estimator, scene, mode
        self.film = (scene.camera.width, scene.camera.height)

    def evaluate(self, states, rows, labels, counters: Counters) -> Proposal:
        """The path tracer's values of the proposals."""
        camera = states["camera"]
        pixels = first_pixels(camera, rows, self.film)
        values = self.estimator.evaluate(self.scene, pixels, camera.sampler(rows, self.film), self.mode, counters)
        return Proposal(np.arange(rows.size), pixels, values)


class BidirectionalTarget(Target):
    """A BDPT sample: every strategy's MIS-weighted contribution, on its own pixel or splatted."""

    streams = ("camera", "light", "wavelengths")

    def __init__(self, estimator: BDPT, scene, mode) -> None:
        self.estimator, self.scene, self.mode = estimator, scene, mode
        self.film = (scene.camera.width, scene.camera.height)

    def evaluate(self, states, rows, labels, counters: Counters) -> Proposal:
        """BDPT's weighted contributions of the proposals."""
        pixels = first_pixels(states["camera"], rows, self.film)
        samplers = {name: states[name].sampler(rows, self.film if name == "camera" else None) for name in self.streams}
        found = self.estimator.evaluate(self.scene, pixels, samplers, self.mode, counters)
        live = np.flatnonzero(found.weighted.any(axis=0))
        return Proposal(found.lane.take(live), found.pixel.take(live), found.weighted.take(live, axis=1))


@dataclass
class PSSMLT(Metropolis):
    """Primary-sample-space MLT; see the module docstring for the parameters."""

    name = "pssmlt"

    over: str = parameter("pt", "the estimator whose samples the chains explore: 'pt' or 'bdpt'",
                          lambda value, name: choice(value, name, OVER))
    max_depth: int = parameter(16, "longest path in segments (finite: a chain's state holds every number its path "
                                    "draws, and each step waits for its longest path)", partial(integer, low=1))
    rr: str | None = p.underlying_rr()
    rr_depth: int | None = p.underlying_rr_depth()
    kernel: str = p.kernel("the underlying estimator's vertices and connections")
    inner: object = field(init=False, repr=False)

    def __post_init__(self) -> None:
        super().__post_init__()
        given = {name: value for name, value in (("rr", self.rr), ("rr_depth", self.rr_depth)) if value is not None}
        self.inner = (PathTracer if self.over == "pt" else BDPT)(max_depth=self.max_depth, kernel=self.kernel,
                                                                 **given)

    def plan(self, scene) -> list[str]:
        """What the chains explore, then the Metropolis settings."""
        return ([f"Kelemen et al.'s primary sample space over {self.over}'s samples:"] + self.inner.plan(scene)
                + super().plan(scene))

    def check(self, scene) -> None:
        """The underlying estimator's checks."""
        self.inner.check(scene)

    def warnings(self, scene) -> list[str]:
        """The underlying estimator's warnings."""
        return self.inner.warnings(scene)

    def prepare(self, scene) -> None:
        """What the underlying estimator builds, and the Metropolis set-up."""
        super().prepare(scene)
        self.inner.prepare(scene)

    def target(self, scene, mode) -> Target:
        """PT's or BDPT's samples."""
        return (PathTarget if self.over == "pt" else BidirectionalTarget)(self.inner, scene, mode)
