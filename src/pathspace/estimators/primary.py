"""Primary sample space for Metropolis chains: states of uniform numbers, mutated lazily (Kelemen et al. 2002).

A chain's state is an infinite vector of numbers in [0, 1) per random
stream (camera, light, ...): the numbers an estimator draws, in the order
it draws them.  A *proposal* either replaces the whole vector by fresh
uniforms (a large step) or moves every number by a small symmetric step on
the circle [0, 1) (a small step).  Both are symmetric, T(x -> y) = T(y -> x),
so the acceptance is min(1, f(y) / f(x)).

Numbers are materialised lazily, as pbrt-v3's MLTSampler does: a number
is brought up to date only when a small step's proposal draws it (a large
step's proposal does not depend on it).  Each number keeps the
count of accepted proposals (``stamp``) when it was last brought up to date;
since then, every accepted small step would have moved it by one step and an
accepted large step would have replaced it.  Those moves never influenced
anything (the number was not used), so bringing it up to date draws them now:
the sum of n independent steps (exact for both kernels: a Gaussian of
sigma sqrt(n), or n exponential steps summed), or a fresh uniform after a
large step.  This is exactly the chain that mutates every number at every
step, at the cost of the numbers used -- except that n exponential steps
cost 2n uniforms, so from :attr:`SmallStep.catch_up_limit` missed steps on
(where their sum modulo 1 is within 1e-12 of uniform in total variation)
the number is replaced by a fresh uniform instead.

:class:`ChainStates` holds the chains' numbers of one stream (fetched and settled
by C kernels, ``ext/primary.c``, tested against :class:`SmallStep`); a
:class:`PrimarySampler` serves a proposal's numbers to an estimator through
the :class:`~pathspace.sampler.Sampler` protocol, so any estimator with an
``evaluate`` on given numbers (PT, BDPT) runs on a chain's proposal unchanged.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Callable

import numpy as np

from .. import _native

__all__ = ["SmallStep", "ChainStates", "PrimarySampler", "KERNELS", "Uniforms", "new_counters", "advance",
           "film_position", "exponential_catch_up_limit"]

KERNELS = ("exponential", "gaussian")
Uniforms = Callable[[int], np.ndarray]  # k -> k uniform numbers in [0, 1) (float64)


@dataclass(frozen=True)
class SmallStep:
    """A symmetric small step on the circle [0, 1).

    ``"exponential"`` (Kelemen et al. 2002, sec. 4.2): |step| = s2 exp(-log(s2/s1) u) for
    uniform u, with a random sign, so |step| in [s1, s2] with density 1 / (|step| log(s2/s1)); ``size`` is
    s2 and s1 = s2 / 16 (the paper's 1/1024 and 1/64).  ``"gaussian"`` (pbrt-v3): a normal step of
    standard deviation ``size``.
    """

    kernel: str = "exponential"
    size: float = 1.0 / 64.0

    def __post_init__(self) -> None:
        if self.kernel not in KERNELS:
            raise ValueError(f"small_step: expected one of {', '.join(KERNELS)}, got {self.kernel!r}")
        if not (np.isfinite(self.size) and 0.0 < self.size <= 0.25):
            raise ValueError(f"step_size: expected a number in (0, 0.25], got {self.size!r}")

    @property
    def smallest(self) -> float:
        """s1 of the exponential kernel."""
        return self.size / 16.0

    @property
    def catch_up_limit(self) -> float:
        """Missed exponential steps from which a number's catch-up draws one fresh uniform (see
        :func:`exponential_catch_up_limit`); the Gaussian kernel's catch-up costs two uniforms at any count."""
        return exponential_catch_up_limit(self.size) if self.kernel == "exponential" else np.inf

    def steps(self, count: np.ndarray, uniforms: Uniforms) -> np.ndarray:
        """The sum of ``count[i]`` independent steps for every i (0 for a count of 0), float64.  The uniforms are
        consumed number after number: a pair per exponential step (magnitude, sign), one pair per number for
        the Gaussian (Box-Muller), one uniform for a number past :attr:`catch_up_limit`.  For one number, this
        is what ``ext/primary.c`` draws to catch it up (the tests' reference for the kernel); path-space MLT's
        wavelength mutation takes single steps from it."""
        count = np.asarray(count, dtype=np.int64)
        out = np.zeros(count.size)
        moved = np.flatnonzero(count > 0)
        if not moved.size:
            return out
        n = count.take(moved)
        if self.kernel == "gaussian":
            u = uniforms(2 * moved.size)
            normal = np.sqrt(-2.0 * np.log1p(-u[0::2])) * np.cos(2.0 * np.pi * u[1::2])  # Box-Muller
            out[moved] = self.size * np.sqrt(n) * normal
            return out
        # Past the limit the sum modulo 1 is uniform to within 1e-12: one uniform (a "step" in [0, 1)) stands
        # for it, so a number's catch-up costs at most 2 * limit uniforms however long it was not used.
        many = n >= self.catch_up_limit
        if many.any():
            out[moved[many]] = uniforms(int(np.count_nonzero(many)))
            moved, n = moved[~many], n[~many]
            if not moved.size:
                return out
        ends = np.cumsum(n)
        total = int(ends[-1])
        # The steps of consecutive numbers are summed in chunks of at most CATCH_UP_CHUNK (a bounded memory).
        for first in range(0, total, CATCH_UP_CHUNK):
            last = min(first + CATCH_UP_CHUNK, total)
            single = self._exponential(uniforms(2 * (last - first)))
            if first == 0 and last == total:
                out[moved] = single if total == moved.size else np.add.reduceat(single, ends - n)
                break
            owner = np.searchsorted(ends, np.arange(first, last), side="right")   # the number of each step
            low = int(owner[0])
            sums = np.bincount(owner - low, weights=single)
            out[moved[low:low + sums.size]] += sums
        return out

    def single(self, count: int, uniforms: Uniforms) -> np.ndarray:
        """``count`` independent single steps (a small step's move of each number), float64."""
        if self.kernel == "gaussian":
            return self.steps(np.ones(count, np.int64), uniforms)
        return self._exponential(uniforms(2 * count))

    def _exponential(self, u: np.ndarray) -> np.ndarray:
        """Exponential steps from uniforms u (2n,), a pair per step: the magnitude, then the sign."""
        return self.size * np.exp(-np.log(16.0) * u[0::2]) * np.where(u[1::2] < 0.5, -1.0, 1.0)

    def pdf(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Density of one step from ``x`` to ``y`` on the circle (per coordinate; symmetric in x and y)."""
        d = np.asarray(y, dtype=np.float64) - np.asarray(x, dtype=np.float64)
        if self.kernel == "gaussian":
            shifts = np.arange(-4, 5)[:, None]   # the wrapped normal: the images of d on the line
            z = (d.reshape(1, -1) + shifts) / self.size
            return (np.exp(-0.5 * z * z).sum(axis=0) / (self.size * np.sqrt(2.0 * np.pi))).reshape(d.shape)
        a = np.abs(d - np.round(d))              # distance on the circle (s2 <= 1/4: one image only)
        with np.errstate(divide="ignore"):
            return np.where((a >= self.smallest) & (a <= self.size), 0.5 / (a * np.log(16.0)), 0.0)


CATCH_UP_CHUNK = 1 << 20   # exponential steps drawn at once by a catch-up (2 uniforms each)
_TOTAL_VARIATION = 1e-12    # how far from uniform a caught-up number replaced by a fresh uniform may be


@lru_cache(maxsize=None)
def exponential_catch_up_limit(size: float) -> float:
    """The number n of exponential small steps (s2 = ``size``, s1 = s2/16) from which their sum modulo 1 is
    within total variation 1e-12 of the uniform distribution on [0, 1).

    On the circle, the sum of n steps has Fourier coefficients phi(2 pi k)^n, with phi the step's
    characteristic function, phi(2 pi k) = g(k s2), g(x) = int_0^1 cos(2 pi x 16^-v) dv (|step| = s2 16^-v,
    v uniform).  By Cauchy-Schwarz and Parseval,
        TV <= 1/2 ||density - 1||_2 = 1/2 (2 sum_{k>=1} phi(2 pi k)^(2n))^(1/2)
           <= rho^(n-1) (A / 2)^(1/2),
    with rho = max_{k>=1} |phi(2 pi k)| and A = sum_{k>=1} phi(2 pi k)^2 = (int p^2 - 1) / 2
    = (15 / (2 s2 log(16)^2) - 1) / 2 (p: the step's density 1 / (2 |d| log 16), unwrapped since s2 <= 1/4).
    rho = g(s2) for every s2 in (0, 1/4]: g decreases on [0, 1/2], and for x >= 1/4, |g(x)| <= g(1/4) = 0.80
    (|Ci(y)| <= 2/y gives |g(x)| <= 17 / (pi x log 16) < 0.8 from x = 2.5; [1/4, 2.5] is checked on a grid
    in the tests).  1 - rho = int_0^1 2 sin^2(pi s2 16^-v) dv ~ 3.55 s2^2 for small s2, so the limit grows as
    1 / s2^2: 125 steps at s2 = 1/4, 2042 at 1/16, 33497 at 1/64 (the default), 8.2e4 at 1/100, 8.6e6 at
    1/1000 (below s2 = 1.1e-9 no int64 count reaches it).
    """
    nodes, weights = np.polynomial.legendre.leggauss(64)
    v = 0.5 * (nodes + 1.0)
    gap = float(np.dot(0.5 * weights, 2.0 * np.sin(np.pi * size * 16.0 ** -v) ** 2))   # 1 - rho
    if gap <= 0.0:
        return np.inf
    a = (15.0 / (2.0 * size * np.log(16.0) ** 2) - 1.0) / 2.0
    return float(1.0 + np.ceil((0.5 * np.log(a / 2.0) - np.log(_TOTAL_VARIATION)) / -np.log1p(-gap)))


class ChainStates:
    """The numbers of one random stream of ``chains`` Markov chains, and the proposal being evaluated.

    Per chain: ``accepted`` (proposals accepted so far) and ``last_large``
    (the count when the last accepted large step was accepted); per number:
    ``current`` (its value, up to date at ``stamp`` accepted proposals; -1:
    never drawn) and ``proposal`` (NaN until the proposal draws it).  With
    ``replay`` set, the proposal is the current state (numbers not drawn
    before are drawn for both).  ``fresh`` states hold no chains (and need
    no ``step``), only proposals of fresh uniforms (independent samples, as
    the bootstrap takes them); :meth:`clear` readies them for the next batch.
    The chains' counters are shared by all streams of the chains: pass the
    same ``counters`` dict to each stream's ChainStates.
    """

    def __init__(self, chains: int, step: SmallStep | None, uniforms: Uniforms,
                 counters: dict[str, np.ndarray] | None = None, width: int = 16, fresh: bool = False) -> None:
        if step is None and not fresh:
            raise ValueError("chains need a small step (only fresh states, which hold no chains, take none)")
        self.step, self.uniforms, self.fresh = step, uniforms, fresh
        self.counters = counters if counters is not None else new_counters(chains)
        # Numbers are stored number by number: (width, chains), so that a wavefront drawing number j of its
        # lanes reads one contiguous row; flat index = j * chains + chain, unchanged when the width grows.
        self.proposal = np.full((width, chains), np.nan)
        self.current = None if fresh else np.zeros((width, chains))
        self.stamp = None if fresh else np.full((width, chains), -1, dtype=np.int64)
        self.drawn: list[np.ndarray] = []   # flat indices of the numbers the proposal has drawn (or was given)
        self.replay = False   # True: the "proposal" is the current state itself (to evaluate a chain's start)
        # primary_fetch's small step: kernel index, size, catch-up limit (fresh states take no step)
        self._kernel = (0, 1.0, np.inf) if step is None else (KERNELS.index(step.kernel), step.size,
                                                              step.catch_up_limit)

    @property
    def chains(self) -> int:
        """Number of chains."""
        return self.proposal.shape[1]

    @property
    def width(self) -> int:
        """Numbers per chain stored so far."""
        return self.proposal.shape[0]

    def _grow(self, width: int) -> None:
        # At least double: a walk draws its numbers a few at a time, and each growth copies every number.
        extra = max(width - self.width, self.width, 16)
        self.proposal = np.concatenate([self.proposal, np.full((extra, self.chains), np.nan)])
        if not self.fresh:
            self.current = np.concatenate([self.current, np.zeros((extra, self.chains))])
            self.stamp = np.concatenate([self.stamp, np.full((extra, self.chains), -1, np.int64)])

    def fetch(self, rows: np.ndarray, columns: np.ndarray) -> np.ndarray:
        """The proposal's numbers ``columns`` of chains ``rows`` (same shapes), drawing those not drawn yet: fresh
        uniforms for fresh states and large steps; else the current numbers, brought up to date, moved by one
        small step (or, with ``replay``, the current numbers themselves).  One pass in C
        (``_native.primary_fetch``): a number's uniforms are the next of the stream, number by number in the
        order asked, its catch-up before its step (what :meth:`SmallStep.steps` and :meth:`SmallStep.single`
        draw for it alone)."""
        rows = np.ascontiguousarray(rows, dtype=np.int64)
        columns = np.ascontiguousarray(columns, dtype=np.int64)
        if int(columns.max(initial=-1)) >= self.width:
            self._grow(int(columns.max()) + 1)
        counters = (None, None, None) if self.fresh else (self.counters["accepted"], self.counters["last_large"],
                                                          self.counters["large"])
        u, drawn = _native.primary_fetch(self.proposal, self.current, self.stamp, rows.reshape(-1),
                                         columns.reshape(-1), *counters, self._mode, *self._kernel, self.uniforms)
        if drawn.size:
            self.drawn.append(drawn)
        return u.reshape(rows.shape)

    @property
    def _mode(self) -> int:
        """primary_fetch's mode: 0 chains stepping, 1 replaying their current state, 2 fresh uniforms."""
        return 2 if self.fresh else 1 if self.replay else 0

    def settle(self, accept: np.ndarray) -> None:
        """End the proposal: the chains ``accept`` (bool per chain) take its numbers, the others keep theirs.
        Call once per stream, then :func:`advance` the shared counters once."""
        if self.drawn:
            _native.primary_settle(self.proposal, self.current, self.stamp, np.concatenate(self.drawn),
                                   np.ascontiguousarray(accept, dtype=bool), self.counters["accepted"])
        self.drawn = []

    def clear(self) -> None:
        """Forget the proposal's numbers (at a cost of the numbers it drew, not of the whole state)."""
        if self.drawn:
            _native.primary_settle(self.proposal, None, None, np.concatenate(self.drawn), None, None)
        self.drawn = []

    def load(self, rows: np.ndarray, numbers: np.ndarray) -> None:
        """Start chains ``rows`` at the given numbers ((k, dims), NaN: never drawn) with fresh counters."""
        if numbers.shape[1] > self.width:
            self._grow(numbers.shape[1])
        width = numbers.shape[1]
        drawn = ~np.isnan(numbers.T)
        # Flat indices of every number of the chains, number by number: the first width x k are those given.
        # (put on flat indices: several times faster than assigning a[:, rows] of a 2-D array.)
        cells = (np.arange(self.width)[:, None] * self.chains + rows).reshape(-1)
        given = cells[:width * rows.size]
        current, stamp = self.current.reshape(-1), self.stamp.reshape(-1)
        current.put(cells, 0.0)
        current.put(given, np.where(drawn, numbers.T, 0.0))
        stamp.put(cells, -1)
        stamp.put(given, np.where(drawn, 0, -1))
        self.proposal.reshape(-1).put(cells, np.nan)
        for name in ("accepted", "last_large"):
            self.counters[name][rows] = 0

    def numbers(self, rows: np.ndarray, proposal: bool = False) -> np.ndarray:
        """(k, width) numbers of chains ``rows``: their current state (as last brought up to date), or the
        proposal's (NaN where it has drawn nothing)."""
        return np.take(self.proposal if proposal else self.current, rows, axis=1).T

    def set_proposal(self, column: int, values: np.ndarray) -> None:
        """Set number ``column`` of the proposals of chains 0 .. ``values.size`` - 1 (e.g. film positions chosen
        by the bootstrap)."""
        if column >= self.width:
            self._grow(column + 1)
        self.proposal[column, :values.size] = values
        self.drawn.append(column * self.chains + np.arange(values.size))

    def sampler(self, rows: np.ndarray, film: tuple[int, int] | None = None) -> "PrimarySampler":
        """A sampler serving the proposal's numbers to the lanes of chains ``rows``."""
        return PrimarySampler(self, np.asarray(rows, dtype=np.int64), film)


def new_counters(chains: int) -> dict[str, np.ndarray]:
    """Counters a chain's streams share: accepted proposals, the count at the last accepted large step, and
    whether the current proposal is a large step."""
    return {"accepted": np.zeros(chains, np.int64), "last_large": np.zeros(chains, np.int64),
            "large": np.zeros(chains, bool)}


def advance(counters: dict[str, np.ndarray], accept: np.ndarray) -> None:
    """Count the accepted proposals (after every stream has :meth:`ChainStates.settle` d)."""
    counters["accepted"] += accept
    taken_large = accept & counters["large"]
    counters["last_large"][taken_large] = counters["accepted"][taken_large]


def film_position(u: np.ndarray, film: tuple[int, int]) -> np.ndarray:
    """The pixel index (N,) of film coordinates ``u`` (2, N) in [0, 1)^2 over a ``film`` = (width, height)
    image (the position inside the pixel is what :class:`PrimarySampler` serves in their place)."""
    width, height = film
    ix = np.minimum(np.floor(u[0] * width), width - 1)
    iy = np.minimum(np.floor(u[1] * height), height - 1)
    return (iy * width + ix).astype(np.int64)


class PrimarySampler:
    """The :class:`~pathspace.sampler.Sampler` of a proposal: lane j draws chain ``rows[j]``'s numbers in order.

    With ``film`` = (width, height), the first two numbers of every lane are
    film coordinates over the whole image, and the sampler serves the
    position inside the lane's pixel instead (see :func:`film_position`).
    """

    def __init__(self, states: ChainStates, rows: np.ndarray, film: tuple[int, int] | None = None) -> None:
        self.states, self.row, self.film = states, rows, film
        self.cursor = np.zeros(rows.size, dtype=np.int64)

    @property
    def lanes(self) -> int:
        """Number of live lanes."""
        return int(self.row.size)

    def draw(self, k: int) -> np.ndarray:
        """The next k numbers of every live lane, (k, lanes)."""
        columns = self.cursor[None, :] + np.arange(k)[:, None]
        rows = np.broadcast_to(self.row[None, :], columns.shape)
        u = self.states.fetch(rows.ravel(), columns.ravel()).reshape(columns.shape)
        if self.film is not None:
            first = columns < 2
            if first.any():
                scaled = u * np.where(columns == 0, self.film[0], self.film[1])
                u = np.where(first, scaled - np.floor(scaled), u)
        self.cursor += k
        return u

    def keep(self, indices: np.ndarray) -> None:
        """Keep the lanes ``indices``."""
        self.row, self.cursor = self.row.take(indices), self.cursor.take(indices)

    def split(self, indices: np.ndarray) -> "PrimarySampler":
        """The lanes ``indices`` leave, with their chains and positions."""
        part = PrimarySampler(self.states, self.row.take(indices), self.film)
        part.cursor = self.cursor.take(indices)
        rest = np.ones(self.row.size, dtype=bool)
        rest[indices] = False
        self.row, self.cursor = self.row[rest], self.cursor[rest]
        return part

    def extend(self, other: "PrimarySampler") -> None:
        """Append the lanes of ``other`` (a sampler of the same chains)."""
        if other.states is not self.states:
            raise ValueError("only samplers of the same chain states can be joined")
        self.row = np.concatenate([self.row, other.row])
        self.cursor = np.concatenate([self.cursor, other.cursor])
