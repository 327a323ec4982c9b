"""Random numbers for wavefronts, reproducible from one seed.

A render is cut into *units* -- one tile of pixels in one pass -- and every
unit draws from its own ``numpy.random.Generator``, seeded by
``SeedSequence(seed, spawn_key=key)`` (the stream ``SeedSequence(seed).spawn``
hands out) with a key that names the unit, never the thread, process or
wavefront that runs it.  A unit's lanes draw together, a row of numbers per
dimension, so the numbers a path receives depend only on its unit: the same
seed gives the same image on one core or two, split across machines, and
whatever else shares the wavefront.

Estimators ask a sampler for ``draw(k)``: k uniform numbers in [0, 1) per live
lane, as a (k, lanes) float64 array; tell it ``keep(indices)`` when lanes
terminate; and ``add(keys, counts, k)`` when new units join the wavefront
(their lanes go last, and get their first k numbers).  The protocol lets a
Markov-chain sampler (primary-sample-space MLT) replay given numbers instead.
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
    """Fresh independent uniforms for a wavefront of lanes grouped in units (lanes ordered unit by unit)."""

    def __init__(self, seed: int, keys: Sequence[tuple[int, ...]] = (), counts: Sequence[int] = ()) -> None:
        self.seed = int(seed)
        self.generators: list[np.random.Generator] = []
        self.unit = np.zeros(0, dtype=np.int64)
        self.counts = np.zeros(0, dtype=np.int64)
        if len(keys):
            self.add(keys, counts, 0)

    @property
    def lanes(self) -> int:
        """Number of live lanes."""
        return int(self.unit.size)

    def add(self, keys: Sequence[tuple[int, ...]], counts: Sequence[int], k: int) -> np.ndarray:
        """Append lanes of new units (``counts[j]`` lanes of unit ``keys[j]``); return their first k numbers."""
        if len(keys) != len(counts):
            raise ValueError("one lane count per unit is required")
        first = len(self.generators)
        new = [unit_generator(self.seed, key) for key in keys]
        draws = [g.random((k, int(c))) for g, c in zip(new, counts)]
        self.generators += new
        self.counts = np.concatenate([self.counts, np.asarray(counts, dtype=np.int64)])
        self.unit = np.concatenate([self.unit, np.repeat(np.arange(first, first + len(keys)), counts)])
        return np.concatenate(draws, axis=1) if draws else np.empty((k, 0))

    def draw(self, k: int) -> np.ndarray:
        """k uniform numbers in [0, 1) for every live lane, shape (k, lanes)."""
        live = np.flatnonzero(self.counts)
        if live.size == 1:
            return self.generators[live[0]].random((k, self.lanes))
        out = np.empty((k, self.lanes))
        start = 0
        for j in live:
            stop = start + int(self.counts[j])
            out[:, start:stop] = self.generators[j].random((k, stop - start))
            start = stop
        return out

    def keep(self, indices: np.ndarray) -> None:
        """Only the lanes at ``indices`` (increasing, of the current live lanes) stay alive."""
        self.unit = self.unit.take(indices)
        self.counts = np.bincount(self.unit, minlength=len(self.generators))
