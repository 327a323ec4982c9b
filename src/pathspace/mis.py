"""Multiple importance sampling: the heuristics, and weights computed from ratios of densities.

One vocabulary for every estimator (Veach 1997, sec. 9.2):

``"balance"``  w_s = p_s / sum_s' p_s';
``"power"``    w_s = p_s^beta / sum_s' p_s'^beta (eq. 9.13; beta = ``mis_beta``, 2 by default);
``"uniform"``  w_s = 1 / (number of strategies that can produce the sample);
``"single"``   only the chosen strategy counts (weight 1 where it can produce the sample);
``"none"``     every strategy counts with weight 1: the estimate is the *sum* of the
               strategies' estimates (for variance figures, not an estimate of the image).

Bidirectional MIS can also be restricted to a subset of the strategies
(:class:`StrategySubset`, e.g. without the s = 0 or t = 0 families): the
others get weight 0 and the weights are renormalised over the subset, so the
image stays unbiased for every path some strategy of the subset can produce.

The path tracer combines two strategies (BSDF sampling and light sampling)
with the first three (:func:`mis_weight`); bidirectional path tracing
combines all of its (s, t) strategies with any of the five
(:func:`mis_weights`, in C; :func:`mis_weights_reference` is the same in
plain Python, for tests).  Weights are always formed from *ratios* of
densities, w = 1 / (1 + sum (p_s' / p_s)^beta), never from products of raw
densities, so they do not over- or underflow on long paths and do not change
when the scene is scaled.  A strategy that cannot produce a sample (density
0: delta vertices, pinhole cameras, point lights) takes no part in the sum.
"""
from __future__ import annotations

import ast
import math
from dataclasses import dataclass

import numpy as np

from . import _native
from .checks import choice, number

__all__ = ["HEURISTICS", "TWO_STRATEGY", "LIGHT_DELTA", "LIGHT_INFINITE", "SubpathPdfs", "Connections", "StrategySubset",
           "check_heuristic", "mis_weight", "mis_weights", "mis_weights_reference"]

HEURISTICS = ("balance", "power", "uniform", "single", "none")
TWO_STRATEGY = ("balance", "power", "uniform")  # the heuristics of the path tracer's two strategies
KERNEL_CODES = {name: code for code, name in enumerate(HEURISTICS)}  # as in ext/mis.c


def check_heuristic(heuristic: str, beta: float, strategy=None, *, allowed=HEURISTICS, max_depth: int = -1):
    """Validate MIS parameters ``mis``, ``mis_beta`` and ``strategy``; return (heuristic, beta, strategy),
    the strategy as a tuple (s, t) for "single", else None."""
    choice(heuristic, "mis", allowed)
    beta = number(beta, "mis_beta", low=0.0, low_open=True, what="a finite number > 0")
    if heuristic != "single":
        if strategy is not None:
            raise ValueError("strategy: only used with mis='single'")
        return heuristic, beta, None
    wrong = ValueError(f"strategy: mis='single' needs (s, t) with s, t >= 0 and s + t >= 2, got {strategy!r}")
    if not (isinstance(strategy, (tuple, list)) and len(strategy) == 2
            and all(isinstance(x, (int, np.integer)) and not isinstance(x, bool) and x >= 0 for x in strategy)):
        raise wrong
    s, t = int(strategy[0]), int(strategy[1])
    if s + t < 2:
        raise wrong
    if 0 < max_depth < s + t - 1:
        raise ValueError(f"strategy: {(s, t)} forms paths of {s + t - 1} segments, longer than max_depth={max_depth}")
    return heuristic, beta, (s, t)


def mis_weight(pdf_a: np.ndarray, pdf_b: np.ndarray, heuristic: str = "power", beta: float = 2.0) -> np.ndarray:
    """Weight of strategy a against strategy b (both pdfs in the same measure), float64."""
    if heuristic not in TWO_STRATEGY:
        raise ValueError(f"MIS heuristic: expected one of {TWO_STRATEGY}, got {heuristic!r}")
    a = np.asarray(pdf_a, dtype=np.float64)
    b = np.asarray(pdf_b, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if heuristic == "uniform":
            ratio = np.where(a > 0, (b > 0).astype(np.float64), np.inf)
        else:
            ratio = b / a  # 0/x -> 0, x/0 -> inf, inf/inf -> nan
            if heuristic == "power":
                ratio = ratio * ratio if beta == 2.0 else ratio ** beta
        weight = np.asarray(1.0 / (1.0 + ratio))  # a = 0 < b: ratio inf, weight 0
    undefined = np.isnan(weight)  # 0/0: neither applies (0); inf/inf: two delta strategies (1/2 each)
    if undefined.any():
        weight = np.where(undefined, np.where(np.isinf(a), 0.5, 0.0), weight)
    return weight


# Flags of the light at a path's x_0 (see ext/mis.c): it cannot be hit; it lies at infinity.
LIGHT_DELTA, LIGHT_INFINITE = 1, 2


@dataclass
class SubpathPdfs:
    """Area-measure densities of the vertices of one kind of subpath, lane after lane.

    ``offset`` (lanes + 1,): vertices of lane j are ``offset[j]`` .. ``offset[j+1]-1``,
    in subpath order (vertex 0 on the light or the camera).  ``fwd``: density
    with which the subpath generated the vertex; ``rev``: with which the other
    direction would have (0 where unknown or delta); ``delta``: specular vertex.
    """

    offset: np.ndarray
    fwd: np.ndarray
    rev: np.ndarray
    delta: np.ndarray


@dataclass
class Connections:
    """One row per connection: strategy, lane, and the densities it changes (see ext/mis.c).

    ``light_flags`` (passed beside) are per connection too: LIGHT_DELTA if the
    light at the path's x_0 cannot be hit by rays, LIGHT_INFINITE if it lies
    at infinity.
    """

    s: np.ndarray
    t: np.ndarray
    lane: np.ndarray
    qs_fwd: np.ndarray
    qs_rev: np.ndarray
    qs_minus_rev: np.ndarray
    pt_fwd: np.ndarray
    pt_rev: np.ndarray
    pt_minus_rev: np.ndarray


def mis_weights(c: Connections, light: SubpathPdfs, eye: SubpathPdfs, light_flags: np.ndarray,
                camera_is_delta: bool, heuristic: str = "power", beta: float = 2.0,
                target: tuple[int, int] = (-1, -1), *, subset: "StrategySubset | None" = None) -> np.ndarray:
    """Weight of every connection, computed in C; with a ``subset``, MIS over its strategies only."""
    allowed = None if subset is None else subset.table(_table_size(c, light, eye))
    return _native.mis_weights(
        np.ascontiguousarray(c.s, np.int32), np.ascontiguousarray(c.t, np.int32), np.ascontiguousarray(c.lane, np.int64),
        np.ascontiguousarray(light.offset, np.int64), np.ascontiguousarray(light.fwd, np.float64),
        np.ascontiguousarray(light.rev, np.float64), np.ascontiguousarray(light.delta, np.uint8),
        np.ascontiguousarray(eye.offset, np.int64), np.ascontiguousarray(eye.fwd, np.float64),
        np.ascontiguousarray(eye.rev, np.float64), np.ascontiguousarray(eye.delta, np.uint8),
        np.ascontiguousarray(light_flags, np.uint8),
        *(np.ascontiguousarray(v, np.float64) for v in (c.qs_fwd, c.qs_rev, c.qs_minus_rev, c.pt_fwd, c.pt_rev,
                                                         c.pt_minus_rev)),
        camera_is_delta=bool(camera_is_delta), heuristic=KERNEL_CODES[heuristic], beta=float(beta),
        target_s=int(target[0]), target_t=int(target[1]), allowed=allowed)


def _table_size(c: Connections, light: SubpathPdfs, eye: SubpathPdfs) -> int:
    """The size of a strategy table that holds every (s, t) of these subpaths."""
    longest = max(int(np.diff(light.offset).max(initial=0)), int(np.diff(eye.offset).max(initial=0)))
    return max(longest, int(np.max(c.s, initial=0)), int(np.max(c.t, initial=0))) * 2 + 2


class StrategySubset:
    """The strategies (s, t) that take part in MIS: a predicate on ``s``, ``t`` and the path length
    ``k`` = s + t - 1 in segments (comparisons, ``and``, ``or``, ``not``, + and -, integers), e.g.
    ``"s != 0 and t != 0"`` (no strategy that hits the light or the lens), or a list of (s, t) pairs."""

    def __init__(self, spec) -> None:
        if isinstance(spec, StrategySubset):
            spec = spec.spec
        if isinstance(spec, str):
            try:
                self._tree = ast.parse(spec, mode="eval").body
                self._evaluate(self._tree, np.zeros(1, np.int64), np.zeros(1, np.int64))
            except (SyntaxError, ValueError) as error:
                raise ValueError(f"mis_strategies: expected a condition on s, t and k such as "
                                 f"'s != 0 and t != 0', got {spec!r} ({error})") from None
            self.pairs = None
        else:
            try:
                self.pairs = {(int(s), int(t)) for s, t in spec}
            except (TypeError, ValueError):
                raise ValueError(f"mis_strategies: expected a condition or a list of (s, t) pairs, got {spec!r}") from None
            if not self.pairs or any(s < 0 or t < 0 or s + t < 2 for s, t in self.pairs):
                raise ValueError(f"mis_strategies: expected (s, t) pairs with s, t >= 0 and s + t >= 2, got {spec!r}")
        self.spec = spec

    def __repr__(self) -> str:
        return f"StrategySubset({self.spec!r})"

    def __eq__(self, other) -> bool:
        return isinstance(other, StrategySubset) and self.table(64).tobytes() == other.table(64).tobytes()

    def table(self, size: int) -> np.ndarray:
        """(size, size) uint8: whether strategy (s, t) takes part."""
        if self.pairs is not None:
            out = np.zeros((size, size), np.uint8)
            for s, t in self.pairs:
                if s < size and t < size:
                    out[s, t] = 1
            return out
        s, t = np.meshgrid(np.arange(size), np.arange(size), indexing="ij")
        return np.broadcast_to(self._evaluate(self._tree, s, t), (size, size)).astype(np.uint8)

    def _evaluate(self, node, s, t):
        if isinstance(node, ast.BoolOp):
            combine = np.logical_and if isinstance(node.op, ast.And) else np.logical_or
            values = [self._evaluate(v, s, t) for v in node.values]
            out = values[0]
            for value in values[1:]:
                out = combine(out, value)
            return out
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.Not, ast.USub)):
            value = self._evaluate(node.operand, s, t)
            return np.logical_not(value) if isinstance(node.op, ast.Not) else -value
        if isinstance(node, ast.Compare):
            left, out = self._evaluate(node.left, s, t), True
            for op, right_node in zip(node.ops, node.comparators):
                right = self._evaluate(right_node, s, t)
                out = np.logical_and(out, _COMPARISONS[type(op)](left, right))
                left = right
            return out
        if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub)):
            a, b = self._evaluate(node.left, s, t), self._evaluate(node.right, s, t)
            return a + b if isinstance(node.op, ast.Add) else a - b
        if isinstance(node, ast.Name) and node.id in ("s", "t", "k"):
            return {"s": s, "t": t, "k": s + t - 1}[node.id]
        if isinstance(node, ast.Constant) and isinstance(node.value, int) and not isinstance(node.value, bool):
            return node.value
        raise ValueError(f"unsupported {ast.dump(node)[:40]}")


_COMPARISONS = {ast.Eq: np.equal, ast.NotEq: np.not_equal, ast.Lt: np.less, ast.LtE: np.less_equal,
                ast.Gt: np.greater, ast.GtE: np.greater_equal}


def mis_weights_reference(c: Connections, light: SubpathPdfs, eye: SubpathPdfs, light_flags: np.ndarray,
                          camera_is_delta: bool, heuristic: str = "power", beta: float = 2.0,
                          target: tuple[int, int] = (-1, -1), *, subset: StrategySubset | None = None) -> np.ndarray:
    """The same weights, written plainly in Python (for tests): the sum over strategies s' of
    (p_s' / p_s)^beta, p_s' / p_s built as a product of p_rev / p_fwd one vertex at a time
    (kept as mantissa and exponent)."""
    def remap0(x):
        return x if x != 0 else 1.0

    def times(r, numerator, denominator):
        """Multiply a (mantissa, exponent) ratio by numerator / denominator without overflow."""
        mn, en = math.frexp(numerator)
        md, ed = math.frexp(denominator)
        mantissa, er = math.frexp(r[0] * (mn / md))
        return mantissa, r[1] + en - ed + er

    def term(r):
        if heuristic == "uniform":
            return 1.0
        exponent = beta if heuristic == "power" else 1.0
        log2_value = exponent * (math.log2(r[0]) + r[1])
        if log2_value >= 1024:
            return math.inf
        if exponent in (1.0, 2.0):
            return math.ldexp(r[0] ** exponent, int(exponent * r[1])) if log2_value > -1100 else 0.0
        return 2.0 ** log2_value

    table = None if subset is None else subset.table(_table_size(c, light, eye))

    def part(s, t):
        return table is None or (s < len(table) and t < len(table) and bool(table[s, t]))

    out = np.zeros(len(c.s))
    for m in range(len(c.s)):
        s, t, lane = int(c.s[m]), int(c.t[m]), int(c.lane[m])
        lo, hi = light.offset[lane], light.offset[lane + 1]
        eo, ei = eye.offset[lane], eye.offset[lane + 1]
        lf, lr, ld = light.fwd[lo:hi], light.rev[lo:hi], light.delta[lo:hi]
        ef, er, ed = eye.fwd[eo:ei], eye.rev[eo:ei], eye.delta[eo:ei]
        light_delta = bool(int(light_flags[m]) & LIGHT_DELTA)
        no_11 = bool(int(light_flags[m]) & LIGHT_INFINITE) and s + t == 2
        if ((s == 0 and light_delta) or (t == 0 and camera_is_delta) or (s == 1 and t == 1 and no_11)
                or (s >= 1 and t >= 1 and s - 1 < len(ld) and ld[s - 1])
                or (t >= 1 and s >= 1 and t - 1 < len(ed) and ed[t - 1]) or not part(s, t)):
            continue
        if heuristic in ("none", "single"):
            out[m] = 1.0 if heuristic == "none" else float((s, t) == tuple(target))
            continue
        total, r = 0.0, (1.0, 0)
        for i in range(t - 1, -1, -1):
            fwd = c.pt_fwd[m] if i == t - 1 else ef[i]
            rev = c.pt_rev[m] if i == t - 1 else (c.pt_minus_rev[m] if i == t - 2 else er[i])
            r = times(r, remap0(rev), remap0(fwd))
            delta_here = False if i == t - 1 else bool(ed[i])
            valid = (not delta_here and not ed[i - 1]) if i > 0 else (not delta_here and not camera_is_delta)
            total += term(r) if valid and not (i == 1 and no_11) and part(s + t - i, i) else 0.0
        r = (1.0, 0)
        for i in range(s - 1, -1, -1):
            fwd = c.qs_fwd[m] if i == s - 1 else lf[i]
            rev = c.qs_rev[m] if i == s - 1 else (c.qs_minus_rev[m] if i == s - 2 else lr[i])
            r = times(r, remap0(rev), remap0(fwd))
            delta_here = False if i == s - 1 else bool(ld[i])
            delta_before = bool(ld[i - 1]) if i > 0 else light_delta
            total += term(r) if (not delta_here and not delta_before and not (i == 1 and no_11)
                                 and part(i, s + t - i)) else 0.0
        out[m] = 1.0 / (1.0 + total)
    return out
