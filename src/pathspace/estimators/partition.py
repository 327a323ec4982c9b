"""A partition of path space between Markov chains and BDPT: the chains own the long paths with a specular vertex.

With ``explore='specular'``, :class:`~pathspace.estimators.mlt.MLT`'s chains sample only paths of more than
``direct`` segments with a specular (delta) vertex among x_1 .. x_{k-1} (their f is 0 elsewhere, see
:class:`~pathspace.estimators.paths.Space`), and :class:`UnexploredBDPT` renders every other path.  Both
sides classify a path by the same property of its vertices, so the two images add up to the whole: every
strategy (s, t) of a path agrees on its class, and setting the MIS weights of a class's connections to 0
leaves BDPT an unbiased estimate of the rest of path space.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from ..checks import integer
from .base import parameter
from .bdpt import BDPT
from .connections import Batch, Contributions

__all__ = ["UnexploredBDPT", "explored"]


def explored(part: Contributions, batch: Batch, direct: int) -> np.ndarray:
    """Whether each BDPT connection of ``part`` makes a path the chains own: more than ``direct`` segments and a
    specular vertex among x_1 .. x_{k-1}.  Strategy (s, t) joins light vertices y_0 .. y_{s-1} to camera
    vertices z_{t-1} .. z_0 (:mod:`pathspace.estimators.connections`), so those are y_1 .. y_{s-1} and
    z_1 .. z_{t-1}; but z_{t-1} is x_0 when s = 0 (the camera subpath found the light), and y_{s-1} is the lens
    point x_k, not a stored vertex, when t = 0 (the light subpath passed through a thin lens)."""
    light = batch.light.any_specular(part.lane, 1, np.where(part.t == 0, part.s - 2, part.s - 1))
    camera = batch.eye.any_specular(part.lane, 1, np.where(part.s == 0, part.t - 2, part.t - 1))
    return (part.s + part.t - 1 > direct) & (light | camera)


@dataclass
class UnexploredBDPT(BDPT):
    """BDPT over the paths the chains leave out (see the module docstring): those of at most ``direct``
    segments, and the longer ones without a specular vertex."""

    direct: int = parameter(0, "paths longer than this with a specular vertex get weight 0 (the chains' part)",
                            partial(integer, low=0))

    def _weights(self, part: Contributions, batch: Batch) -> np.ndarray:
        return np.where(explored(part, batch, self.direct), 0.0, super()._weights(part, batch))
