"""Random numbers for wavefronts, reproducible from one seed.

A render is cut into *units* -- one tile of pixels in one pass -- and every
unit draws from its own ``numpy.random.Generator``, seeded by
``SeedSequence(seed, spawn_key=key)`` (the stream ``SeedSequence(seed).spawn``
hands out) with a key that names the unit, never the thread, process or
wavefront that runs it.  So the same seed gives the same image on one core,
on two, or split across machines, and a render of n passes is a prefix of
one with more.

Estimators ask a sampler for ``draw(k)``: k uniform numbers in [0, 1) per live
lane, as a (k, lanes) float64 array, and tell it ``keep(indices)`` when lanes
terminate.  The protocol lets a Markov-chain sampler (primary-sample-space
MLT) replay given numbers instead.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["StreamSampler", "unit_generator"]


def unit_generator(seed: int, key: tuple[int, ...]) -> np.random.Generator:
    """The Generator of the unit ``key`` of a render with ``seed``."""
    spawn_key = tuple(int(k) for k in key)
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(int(seed), spawn_key=spawn_key)))


class StreamSampler:
    """Fresh independent uniforms for a wavefront made of consecutive units.

    ``counts[j]`` lanes belong to unit ``keys[j]``; lanes are ordered unit by
    unit, and stay so as lanes terminate, so each unit's lanes draw from its
    own stream whatever else shares the wavefront.
    """

    def __init__(self, seed: int, keys: Sequence[tuple[int, ...]], counts: Sequence[int]) -> None:
        if len(keys) != len(counts):
            raise ValueError("one lane count per unit is required")
        self.generators = [unit_generator(seed, key) for key in keys]
        self.counts = np.asarray(counts, dtype=np.int64)
        self.unit = np.repeat(np.arange(len(keys)), self.counts)

    @property
    def lanes(self) -> int:
        """Number of live lanes."""
        return int(self.unit.size)

    def draw(self, k: int) -> np.ndarray:
        """k uniform numbers in [0, 1) for every live lane, shape (k, lanes)."""
        if len(self.generators) == 1:
            return self.generators[0].random((k, self.lanes))
        parts = [g.random((k, int(c))) for g, c in zip(self.generators, self.counts) if c]
        return np.concatenate(parts, axis=1) if parts else np.empty((k, 0))

    def keep(self, indices: np.ndarray) -> None:
        """Only the lanes at ``indices`` (increasing, of the current live lanes) stay alive."""
        self.unit = self.unit.take(indices)
        self.counts = np.bincount(self.unit, minlength=len(self.generators))
