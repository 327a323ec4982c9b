"""Random numbers for wavefronts: the sampler protocol, seeded streams, and recorded or given numbers.

An estimator never creates its random numbers; it is handed a
:class:`SamplerSource` and opens a :class:`Sampler` for the lanes it starts.
A sampler serves a wavefront of lanes, one row of numbers per dimension:

``draw(k)``      k uniform numbers in [0, 1) per live lane, a (k, lanes) float64 array;
``keep(idx)``    only the lanes ``idx`` (increasing) stay alive -- call it whenever lanes end;
``extend(s)``    the lanes of another sampler join (after the existing ones);
``split(idx)``   the lanes ``idx`` leave for a sampler of their own (which is returned).

A lane's numbers depend only on its unit and on the order of the draws its
unit's lanes make, wherever those lanes are: a unit's lanes split over two
samplers draw from the same stream, in the order the samplers draw.

Lanes belong to *units* named by integer keys: one tile of pixels in one
pass, and for estimators with several independent streams (camera subpath,
light subpath, wavelengths) a role number appended to the key.  A source
opens samplers for the lanes of given units.  Sources:

:class:`StreamSamplers`
    the renderer's numbers: every unit draws from its own
    ``numpy.random.Generator`` seeded by ``SeedSequence(seed, spawn_key=key)``
    (the stream ``SeedSequence(seed).spawn`` hands out), so the numbers a
    lane receives depend only on its unit and the order of its own draws --
    the same seed gives the same image on one core or two, split across
    machines, and whatever else shares the wavefront;
:class:`RecordingSamplers`
    any source, with every number each lane receives written down
    (:class:`Recording`);
:class:`ReplaySamplers`
    numbers given per lane (a recording, or arrays of primary samples): the
    same numbers give the bit-identical image.  A lane that needs more numbers
    than it was given raises, or draws the rest from a Generator if one is
    given (as primary-sample-space Metropolis sampling extends its state
    lazily).
"""
from __future__ import annotations

from typing import Protocol, Sequence

import numpy as np

__all__ = ["Sampler", "SamplerSource", "StreamSampler", "StreamSamplers", "RecordingSamplers", "Recording",
           "ReplaySampler", "ReplaySamplers", "unit_generator"]

Key = tuple[int, ...]


class Sampler(Protocol):
    """Uniform numbers for a wavefront of lanes (see the module docstring)."""

    @property
    def lanes(self) -> int:
        """Number of live lanes."""

    def draw(self, k: int) -> np.ndarray:
        """k uniform numbers in [0, 1) for every live lane, shape (k, lanes), float64."""

    def keep(self, indices: np.ndarray) -> None:
        """Only the lanes at ``indices`` (increasing, of the current live lanes) stay alive."""

    def extend(self, other: "Sampler") -> None:
        """Append the lanes of ``other`` (a sampler of the same kind) after the live lanes."""

    def split(self, indices: np.ndarray) -> "Sampler":
        """Remove the lanes at ``indices`` (increasing) and return a sampler of them, in that order."""


class SamplerSource(Protocol):
    """Opens samplers for the lanes of units."""

    def open(self, keys: Sequence[Key], counts: Sequence[int]) -> Sampler:
        """A sampler over ``counts[j]`` lanes of unit ``keys[j]`` for every j, unit after unit."""


def unit_generator(seed: int, key: Key) -> np.random.Generator:
    """The Generator of the unit ``key`` of a render with ``seed``."""
    spawn_key = tuple(int(k) for k in key)
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(int(seed), spawn_key=spawn_key)))


def _check_units(keys: Sequence[Key], counts: Sequence[int]) -> None:
    if len(keys) != len(counts):
        raise ValueError(f"one lane count per unit is required, got {len(keys)} keys and {len(counts)} counts")


class StreamSampler:
    """Independent uniforms for lanes grouped in units, one Generator per unit.

    Lanes are ordered segment by segment: a segment is a run of lanes that
    draw from one Generator (a unit, or the part of a unit that joined by
    :meth:`extend` or :meth:`split`); two segments may share a Generator and
    then draw from it in their order.
    """

    def __init__(self, seed: int, keys: Sequence[Key] = (), counts: Sequence[int] = ()) -> None:
        _check_units(keys, counts)
        self.seed = int(seed)
        self.generators = [unit_generator(self.seed, key) for key in keys]
        self.counts = np.asarray(counts, dtype=np.int64).reshape(-1)
        self.unit = np.repeat(np.arange(len(keys)), self.counts)

    @property
    def lanes(self) -> int:
        """Number of live lanes."""
        return int(self.unit.size)

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
        if len(self.generators) == 1:   # one segment (a work item's walk, mostly): no lookups, a few us a bounce
            self.unit = self.unit[:len(indices)]
            self.counts = np.array([self.unit.size], dtype=np.int64)
            return
        self.unit = self.unit.take(indices)
        self.counts = self._counts(self.unit)
        if len(self.generators) > 8 and np.count_nonzero(self.counts) < len(self.generators) // 2:
            self._compact()

    def _counts(self, unit: np.ndarray) -> np.ndarray:
        """Live lanes per segment, of lanes whose segments ``unit`` never decrease (lanes stay in segment order)."""
        return np.diff(np.searchsorted(unit, np.arange(len(self.generators) + 1)))

    def _compact(self) -> None:
        """Forget the segments without live lanes (renumbering the others in order)."""
        live = np.flatnonzero(self.counts)
        renumber = np.zeros(len(self.generators), dtype=np.int64)
        renumber[live] = np.arange(live.size)
        self.generators = [self.generators[j] for j in live]
        self.unit = renumber.take(self.unit)
        self.counts = self.counts.take(live)

    def extend(self, other: "StreamSampler") -> None:
        """Append the lanes (and segments) of ``other``."""
        self.unit = np.concatenate([self.unit, other.unit + len(self.generators)])
        self.counts = np.concatenate([self.counts, other.counts])
        self.generators = self.generators + other.generators

    def split(self, indices: np.ndarray) -> "StreamSampler":
        """The lanes ``indices`` leave, as a sampler of their own drawing from the same Generators."""
        part = StreamSampler(self.seed)
        part.generators = self.generators
        part.unit = self.unit.take(indices)
        part.counts = part._counts(part.unit)
        part._compact()
        rest = np.ones(self.lanes, dtype=bool)
        rest[indices] = False
        self.keep(np.flatnonzero(rest))
        return part


class StreamSamplers:
    """The renderer's source: a :class:`StreamSampler` per opened set of units, seeded by ``seed``."""

    def __init__(self, seed: int) -> None:
        self.seed = int(seed)

    def open(self, keys: Sequence[Key], counts: Sequence[int]) -> StreamSampler:
        """A sampler over the lanes of the units ``keys``."""
        return StreamSampler(self.seed, keys, counts)


class Recording:
    """The numbers each lane of each unit received, in the order it drew them.

    ``numbers(key)`` is a (lanes, dims) float64 array, NaN past the numbers a
    lane drew (lanes that ended early draw fewer).
    """

    def __init__(self) -> None:
        self._draws: dict[Key, list[tuple[np.ndarray, np.ndarray]]] = {}
        self._counts: dict[Key, int] = {}

    def _open(self, key: Key, count: int) -> None:
        if key in self._counts:
            raise ValueError(f"unit {key} was opened twice")
        self._counts[key] = int(count)
        self._draws[key] = []

    def _add(self, key: Key, lanes: np.ndarray, numbers: np.ndarray) -> None:
        self._draws[key].append((lanes, numbers))

    @property
    def keys(self) -> list[Key]:
        """The units recorded, in the order they were opened."""
        return list(self._counts)

    def numbers(self, key: Key) -> np.ndarray:
        """(lanes, dims) numbers of unit ``key``; NaN where a lane drew no more."""
        count = self._counts[key]
        drawn = np.zeros(count, dtype=np.int64)
        columns: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        for lanes, numbers in self._draws[key]:
            columns.append((lanes, drawn.take(lanes), numbers))
            drawn[lanes] += numbers.shape[0]
        out = np.full((count, int(drawn.max(initial=0))), np.nan)
        for lanes, first, numbers in columns:
            for j in range(numbers.shape[0]):
                out[lanes, first + j] = numbers[j]
        return out


class RecordingSampler:
    """A sampler that writes down every number its lanes draw from an inner sampler."""

    def __init__(self, inner: Sampler, recording: Recording, keys: Sequence[Key], counts: Sequence[int]) -> None:
        self.inner = inner
        self.recording = recording
        self.unit_keys = list(keys)
        self.unit = np.repeat(np.arange(len(keys)), np.asarray(counts, dtype=np.int64))
        self.lane = np.concatenate([np.arange(c) for c in counts]) if len(counts) else np.zeros(0, np.int64)

    @property
    def lanes(self) -> int:
        """Number of live lanes."""
        return self.inner.lanes

    def draw(self, k: int) -> np.ndarray:
        """The inner sampler's numbers, recorded per lane."""
        u = self.inner.draw(k)
        for j in np.unique(self.unit):
            mine = np.flatnonzero(self.unit == j)
            self.recording._add(self.unit_keys[j], self.lane[mine], u[:, mine].copy())
        return u

    def keep(self, indices: np.ndarray) -> None:
        """Keep the lanes ``indices``."""
        self.inner.keep(indices)
        self.unit, self.lane = self.unit.take(indices), self.lane.take(indices)

    def extend(self, other: "RecordingSampler") -> None:
        """Append the lanes of ``other``."""
        self.inner.extend(other.inner)
        self.unit = np.concatenate([self.unit, other.unit + len(self.unit_keys)])
        self.lane = np.concatenate([self.lane, other.lane])
        self.unit_keys = self.unit_keys + other.unit_keys

    def split(self, indices: np.ndarray) -> "RecordingSampler":
        """The lanes ``indices`` leave, still recording."""
        part = RecordingSampler(self.inner.split(indices), self.recording, [], [])
        part.unit_keys, part.unit, part.lane = self.unit_keys, self.unit.take(indices), self.lane.take(indices)
        rest = np.ones(self.unit.size, dtype=bool)
        rest[indices] = False
        self.unit, self.lane = self.unit[rest], self.lane[rest]
        return part


class RecordingSamplers:
    """Wraps a source; every number drawn from the samplers it opens is kept in ``recording``."""

    def __init__(self, source: SamplerSource) -> None:
        self.source = source
        self.recording = Recording()

    def open(self, keys: Sequence[Key], counts: Sequence[int]) -> RecordingSampler:
        """The inner source's sampler for these units, recording."""
        _check_units(keys, counts)
        for key, count in zip(keys, counts):
            self.recording._open(tuple(key), count)
        return RecordingSampler(self.source.open(keys, counts), self.recording, [tuple(k) for k in keys], counts)


class ReplaySampler:
    """Serves given numbers: lane j draws row j of ``numbers`` (lanes, dims) from its first column on.

    A lane asking beyond its row raises ValueError, unless ``rest`` (a
    Generator) is given: then further numbers are drawn from it and appended
    to the lane's row (``numbers`` grows), so the row always holds every
    number the lane used.  NaN entries count as missing.
    """

    def __init__(self, numbers: np.ndarray, rest: np.random.Generator | None = None) -> None:
        numbers = np.asarray(numbers, dtype=np.float64)
        if numbers.ndim != 2:
            raise ValueError(f"numbers: expected a (lanes, dims) array, got shape {numbers.shape}")
        self.numbers = numbers
        self.rest = rest
        self.row = np.arange(numbers.shape[0])
        self.cursor = np.zeros(numbers.shape[0], dtype=np.int64)

    @property
    def lanes(self) -> int:
        """Number of live lanes."""
        return int(self.row.size)

    def draw(self, k: int) -> np.ndarray:
        """The next k numbers of every live lane, (k, lanes)."""
        end = int(self.cursor.max(initial=0)) + k
        if end > self.numbers.shape[1]:
            pad = np.full((self.numbers.shape[0], end - self.numbers.shape[1]), np.nan)
            self.numbers = np.concatenate([self.numbers, pad], axis=1)
        rows = np.broadcast_to(self.row[None, :], (k, self.row.size))
        columns = self.cursor[None, :] + np.arange(k)[:, None]
        u = self.numbers[rows, columns]
        missing = np.isnan(u)
        if missing.any():
            if self.rest is None:
                lane = int(np.flatnonzero(missing.any(axis=0))[0])
                raise ValueError(f"lane {int(self.row[lane])} needs more than the numbers it was given "
                                 f"({int(np.count_nonzero(~np.isnan(self.numbers[self.row[lane]])))})")
            u[missing] = self.rest.random(int(missing.sum()))
            self.numbers[rows[missing], columns[missing]] = u[missing]
        self.cursor += k
        return u

    def keep(self, indices: np.ndarray) -> None:
        """Keep the lanes ``indices``."""
        self.row, self.cursor = self.row.take(indices), self.cursor.take(indices)

    def split(self, indices: np.ndarray) -> "ReplaySampler":
        """The lanes ``indices`` leave, with their rows and positions."""
        part = ReplaySampler(self.numbers, self.rest)
        part.row, part.cursor = self.row.take(indices), self.cursor.take(indices)
        rest = np.ones(self.row.size, dtype=bool)
        rest[indices] = False
        self.row, self.cursor = self.row[rest], self.cursor[rest]
        return part

    def extend(self, other: "ReplaySampler") -> None:
        """Append the lanes of ``other`` (its rows are appended to ``numbers``)."""
        width = max(self.numbers.shape[1], other.numbers.shape[1])
        mine, theirs = (np.pad(a, ((0, 0), (0, width - a.shape[1])), constant_values=np.nan)
                        for a in (self.numbers, other.numbers))
        self.row = np.concatenate([self.row, other.row + self.numbers.shape[0]])
        self.cursor = np.concatenate([self.cursor, other.cursor])
        self.numbers = np.concatenate([mine, theirs])


class ReplaySamplers:
    """A source that serves each unit's given numbers: ``numbers[key]`` is (lanes, dims) (e.g. a recording)."""

    def __init__(self, numbers: "Recording | dict[Key, np.ndarray]", rest: np.random.Generator | None = None) -> None:
        self.numbers = numbers
        self.rest = rest

    def open(self, keys: Sequence[Key], counts: Sequence[int]) -> ReplaySampler:
        """A replay sampler over the given numbers of these units."""
        _check_units(keys, counts)
        rows = []
        for key, count in zip(keys, counts):
            key = tuple(key)
            try:
                numbers = (self.numbers.numbers(key) if isinstance(self.numbers, Recording)
                           else np.asarray(self.numbers[key], dtype=np.float64))
            except KeyError:
                raise ValueError(f"no numbers were given for unit {key}") from None
            if numbers.ndim != 2 or numbers.shape[0] != count:
                raise ValueError(f"unit {key}: expected numbers for {count} lanes, got shape {numbers.shape}")
            rows.append(numbers)
        width = max((r.shape[1] for r in rows), default=0)
        rows = [np.pad(r, ((0, 0), (0, width - r.shape[1])), constant_values=np.nan) for r in rows]
        return ReplaySampler(np.concatenate(rows) if rows else np.zeros((0, 0)), self.rest)
