"""Bookkeeping of a persistent wavefront: many work items in flight, lanes refilled as paths end.

Paths end at different depths, so a wavefront started from one work item
shrinks to a long tail of nearly empty bounces.  Instead, new items join the
wavefront whenever it falls below a threshold; each lane remembers which
item and pixel sample it belongs to, finished paths are written to their
item's buffer, and an item is handed back as soon as its last path ends.
"""
from __future__ import annotations

import numpy as np

from .. import _native

__all__ = ["ItemBook", "Lanes", "place_lanes", "take_lanes"]


class ItemBook:
    """Result buffers of the work items in flight.

    Every sample of every item gets a *ticket*: the items' samples are
    numbered consecutively in the order the items were opened, so one integer
    per lane says where its result goes.  Lanes keep the order in which they
    joined, so the tickets of live lanes are always increasing.
    """

    def __init__(self, channels: int) -> None:
        self.channels = channels
        self.first: list[int] = []      # first ticket of each open item, increasing
        self.open_items: list = []
        self.values: list[np.ndarray] = []
        self.remaining: list[int] = []
        self._next_ticket = 0

    def open(self, item, count: int) -> np.ndarray:
        """Start an item (any key: a work item, a name) of ``count`` samples; return their tickets."""
        tickets = np.arange(self._next_ticket, self._next_ticket + count, dtype=np.int64)
        self.first.append(self._next_ticket)
        self.open_items.append(item)
        self.values.append(np.zeros((self.channels, count)))
        self.remaining.append(count)
        self._next_ticket += count
        return tickets

    def store(self, tickets: np.ndarray, values: np.ndarray) -> None:
        """Write finished samples ``values`` (C, k) of the lanes holding increasing ``tickets``."""
        bounds = np.searchsorted(tickets, self.first + [self._next_ticket]).tolist()
        for j, first in enumerate(self.first):
            lo, hi = bounds[j], bounds[j + 1]
            if hi > lo:
                where = tickets[lo:hi] - first
                item = self.values[j]
                for c in range(self.channels):   # put released the GIL in a two-thread test; item[:, where] = ...
                    item[c].put(where, values[c, lo:hi])   # held it
                self.remaining[j] -= hi - lo

    def finished(self) -> list[tuple[object, np.ndarray]]:
        """Items whose every sample is done, removed from the book, in the order they were opened."""
        out = []
        for j in reversed(range(len(self.remaining))):
            if self.remaining[j] == 0:
                out.append((self.open_items.pop(j), self.values.pop(j)))
                del self.first[j], self.remaining[j]
        return out[::-1]


def take_lanes(indices: np.ndarray, *arrays: np.ndarray) -> list[np.ndarray]:
    """``np.take(a, indices, axis=-1)`` of every array (lanes along the last axis), in one C call that releases
    the GIL (``ext/lanes.c``): a wavefront's compaction, every bounce.  ``indices``: integers in 0 .. N - 1
    (unlike ``np.take``, no negative ones: IndexError)."""
    indices = np.ascontiguousarray(indices).astype(np.int64, casting="safe", copy=False)
    return _native.take_lanes(indices, list(arrays))


def place_lanes(positions: list[np.ndarray], parts: list[list[np.ndarray]]) -> list[np.ndarray]:
    """Parts of a wavefront placed into one: for every field f, an array ``out`` with ``out[..., positions[p]] =
    parts[p][f]`` for every part p -- ``np.concatenate`` over the parts of field f, gathered into the inverse
    order -- in one C call that releases the GIL (``ext/lanes.c``).  ``positions``: integer arrays that cover
    0 .. N - 1 once each, N their total size (else ValueError).  A field has the type ``np.concatenate`` would
    give it, in native byte order; bool or numeric, lanes along the last of one or two axes (else TypeError)."""
    positions = [np.ascontiguousarray(at).astype(np.int64, casting="safe", copy=False) for at in positions]
    columns = []
    for column in zip(*parts):
        dtype = np.result_type(*column).newbyteorder("=")
        columns.append([np.ascontiguousarray(a, dtype=dtype) for a in column])
    fields = [list(part) for part in zip(*columns)] if columns else [[] for _ in parts]
    return _native.place_lanes(positions, fields, sum(at.size for at in positions))


class Lanes:
    """Per-lane state arrays (lanes along the last axis), compacted and extended together."""

    def __init__(self, fields: tuple[str, ...], **arrays: np.ndarray) -> None:
        self.fields = fields
        for name in fields:
            setattr(self, name, arrays[name])

    @property
    def size(self) -> int:
        return int(getattr(self, self.fields[0]).shape[-1])

    def keep(self, indices: np.ndarray) -> None:
        """Keep only the lanes ``indices`` (int64)."""
        for name, kept in zip(self.fields, take_lanes(indices, *(getattr(self, name) for name in self.fields))):
            setattr(self, name, kept)

    def split(self, indices: np.ndarray) -> "Lanes":
        """Remove the lanes ``indices`` (increasing int64) and return them as lanes of their own."""
        part = Lanes(self.fields, **dict(zip(self.fields, take_lanes(indices, *(getattr(self, name)
                                                                             for name in self.fields)))))
        rest = np.ones(self.size, dtype=bool)
        rest[indices] = False
        self.keep(np.flatnonzero(rest))
        return part

    def add(self, name: str, values: np.ndarray) -> None:
        """A new field ``name`` with ``values`` for the current lanes."""
        self.fields = self.fields + (name,)
        setattr(self, name, values)

    def extend(self, other: "Lanes") -> None:
        """Append the lanes of ``other``."""
        for name in self.fields:
            setattr(self, name, np.concatenate([getattr(self, name), getattr(other, name)], axis=-1))
