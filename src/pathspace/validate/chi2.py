"""Chi-square goodness-of-fit tests of samplers against their densities, over a 2-D domain.

What a test does (Mitsuba 3's ``chi2.ChiSquareTest`` is the model in
spirit; the bins, the quadrature and the treatment of edges differ):

1. Draw ``sample_count`` samples from uniforms and histogram the valid ones
   over the cells of a *domain* (:mod:`pathspace.validate.domains`): the
   sphere of directions in equal-solid-angle (cos theta, phi) cells, a
   zoomed spherical cap about an axis (fine cells where a narrow lobe puts
   its mass), or a rectangle of the plane (a triangle's barycentric domain,
   a lens disk, the film).
2. Integrate the claimed density over every cell: exactly where the caller
   gives the integral (``integral=``), otherwise by adaptive Gauss-Legendre
   quadrature.  Where the caller gives the *support* (``support=``, a
   :class:`~pathspace.validate.domains.Support`: a cone, the spherical
   triangle a light subtends, a hemisphere, a disk, a polygon), cells cut
   by its boundary are integrated over the support only -- along every
   quadrature line the boundary crossings are computed in closed form and
   the line is integrated between them, cells are split where the
   boundary enters them, and u is integrated in a variable that smooths the
   square-root behaviour where lines of constant u touch the boundary (see
   :func:`integrate_bins`) -- so no sliver of support is missed, nothing is
   integrated outside it, and a density constant on a cone, a spherical
   triangle, a disk or a triangle integrates to 1 within about 1e-12.
   Without a support, cells whose nodes see both zero and nonzero density
   are refined to the maximum depth (edges of unknown shape can still cost
   the integral a few 1e-3: give the support where it is known).
3. Samples *outside the support* fail the test: a sample is outside when
   the density is zero (or the support excludes it) at the sample and at
   its eight neighbours ``edge_tolerance`` away (radians on the sphere; a
   fraction of the rectangle's larger side in the plane).  A correct
   sampler never puts a sample there (rounding float32 samples moves them
   about 1e-7), so samples near an edge are never rejected, however thin
   the support is in their cell -- unlike a rule that rejects samples in
   cells whose *integrated* density is zero, which quadrature can get
   wrong at edges.
4. Samples that are invalid (absorbed, failed) or fall outside a zoomed
   domain form one more category, whose expected count is what the density
   leaves of one outside the domain; cells with expected counts below 5
   are pooled (smallest first, until the pool expects 5), and Pearson's
   statistic gives the p-value on (categories - 1) degrees of freedom.
5. The test fails if the p-value is below the significance level
   (Sidak-corrected for ``test_count`` tests of a family), if any sample
   is outside the support or not finite, or if the density integrates to
   more than 1 + ``integral_tolerance`` over the domain.  The integral over
   the domain and the quadrature's error estimate are reported.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Union

import numpy as np

from .domains import PlaneDomain, SphereDomain, Support

Domain = Union[SphereDomain, PlaneDomain]

__all__ = ["ChiSquareResult", "chi2_test", "chi2_test_directions", "integrate_bins", "sidak_significance"]

MIN_EXPECTED = 5.0
_CHUNK = 1 << 21  # points per pdf call


def sidak_significance(alpha: float, test_count: int) -> float:
    """Per-test significance so that ``test_count`` independent tests have family-wise error ``alpha``."""
    return 1.0 - (1.0 - alpha) ** (1.0 / max(int(test_count), 1))


@dataclass
class ChiSquareResult:
    """Outcome of a chi-square test; ``str()`` gives a readable report.

    ``pdf_integral``: the density's integral over the domain;
    ``integral_error``: the quadrature's error estimate for it (0 for exact
    integrals); ``outside``: samples outside the support; ``outside_domain``:
    valid samples beyond a zoomed domain; ``nonfinite``: valid samples with a
    NaN or infinite coordinate; ``invalid``: samples the sampler marked
    invalid; ``observed``/``expected``: counts per cell (res_u, res_v);
    ``reasons``: why the test failed (empty if it passed).
    """

    passed: bool
    statistic: float
    dof: int
    p_value: float
    significance: float
    pdf_integral: float
    message: str
    observed: np.ndarray
    expected: np.ndarray
    integral_error: float = 0.0
    outside: int = 0
    outside_domain: int = 0
    nonfinite: int = 0
    invalid: int = 0
    domain: str = ""
    reasons: list[str] = field(default_factory=list)

    def __str__(self) -> str:
        extra = f", outside support={self.outside}" if self.outside else ""
        extra += f", non-finite={self.nonfinite}" if self.nonfinite else ""
        return (f"{'PASSED' if self.passed else 'FAILED'}: {self.message} (chi2={self.statistic:.1f}, dof={self.dof}, "
                f"p={self.p_value:.3g}, significance={self.significance:.3g}, pdf integral={self.pdf_integral:.6f}"
                f" +- {self.integral_error:.1g}{extra}, invalid={self.invalid}, beyond domain={self.outside_domain}; "
                f"{self.domain})")


# -- quadrature ---------------------------------------------------------------------------------------


def _evaluate(pdf: Callable, points: np.ndarray) -> np.ndarray:
    """``pdf`` at points (D, N) as float64 (N,), in chunks of at most _CHUNK points."""
    count = points.shape[1]
    if count == 0:
        return np.zeros(0)
    if count <= _CHUNK:
        return np.asarray(pdf(points), dtype=np.float64).reshape(count)
    return np.concatenate([np.asarray(pdf(points[:, k:k + _CHUNK]), dtype=np.float64).reshape(-1)
                           for k in range(0, count, _CHUNK)])


def _split(lo: np.ndarray, hi: np.ndarray, cuts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Intervals [lo, hi] (R,) cut at ``cuts`` (R, m) (NaN: none): (a, b, row) of the pieces of positive length."""
    rows = lo.size
    if cuts.shape[1] == 0:
        return lo, hi, np.arange(rows)
    cuts = np.where((cuts > lo[:, None]) & (cuts < hi[:, None]), cuts, np.nan)
    edges = np.sort(np.concatenate((lo[:, None], cuts, hi[:, None]), axis=1), axis=1)
    edges = np.where(np.isnan(edges), hi[:, None], edges)
    a, b = edges[:, :-1], edges[:, 1:]
    keep = b > a
    row = np.broadcast_to(np.arange(rows)[:, None], a.shape)
    return a[keep], b[keep], row[keep]


def _u_of(a: np.ndarray, b: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """u = a + (b - a) sin^2(pi tau / 2) on an interval [a, b] between breaks, and du / dtau."""
    half = 0.5 * np.pi * tau
    return a + (b - a) * np.sin(half) ** 2, 0.5 * np.pi * (b - a) * np.sin(2.0 * half)


def _tau_of(a: np.ndarray, b: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The inverse of :func:`_u_of` (NaN stays NaN)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return (2.0 / np.pi) * np.arcsin(np.sqrt(np.clip((u - a) / (b - a), 0.0, 1.0)))


def _refine_segments(domain: Domain, pdf: Callable, u: np.ndarray, a: np.ndarray, b: np.ndarray, coarse: np.ndarray,
                     nodes: np.ndarray, weights: np.ndarray, tolerance: float, max_depth: int = 12
                     ) -> tuple[np.ndarray, bool]:
    """Adaptive Gauss-Legendre along v of the pdf on segments [a, b] of lines of constant u, given their
    one-panel integrals ``coarse``: halved until the halves agree with the whole within ``tolerance``
    (relative).  Returns the integrals and whether every value was finite and non-negative."""
    total = np.zeros(a.size)
    owner = np.arange(a.size)
    ok = True
    for depth in range(max_depth + 1):
        m = 0.5 * (a + b)
        lo, hi = np.concatenate((a, m)), np.concatenate((m, b))
        vv = lo[:, None] + (hi - lo)[:, None] * nodes[None, :]
        values = _evaluate(pdf, domain.from_uv(np.repeat(np.tile(u, 2), nodes.size), vv.ravel()))
        ok &= bool(np.all(np.isfinite(values)) and not np.any(values < 0))
        halves = (values.reshape(-1, nodes.size) @ weights) * (hi - lo)
        fine = halves[:a.size] + halves[a.size:]
        done = (np.abs(fine - coarse) <= tolerance * np.abs(fine)) | (depth == max_depth)
        np.add.at(total, owner[done], fine[done])
        keep = ~done
        if not keep.any():
            break
        owner, u = np.tile(owner[keep], 2), np.tile(u[keep], 2)
        a, b = np.concatenate((a[keep], m[keep])), np.concatenate((m[keep], b[keep]))
        coarse = np.concatenate((halves[:m.size][keep], halves[m.size:][keep]))
    return total, ok


def _cut(domain: Domain, support: Support | None, a: np.ndarray, b: np.ndarray, t0: np.ndarray, t1: np.ndarray,
         v0: np.ndarray, v1: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rectangles [t0, t1] x [v0, v1] cut in tau where the support's boundary crosses their edges v0 and
    v1, so that the support's length along u has no kink inside any of them: (t0, t1, row) of the pieces.
    Cutting the rectangles themselves, rather than integrating the pieces inside one rectangle, lets every
    piece be halved when its rectangle is refined (a piece that never straddles its rectangle's midline
    would otherwise keep its quadrature error unseen)."""
    if support is None:
        return t0, t1, np.arange(t0.size)
    cuts = np.concatenate((support.edge_crossings(domain, v0), support.edge_crossings(domain, v1)), axis=1)
    return _split(t0, t1, _tau_of(a[:, None], b[:, None], cuts))


def _rects(domain: Domain, pdf: Callable, support: Support | None, a: np.ndarray, b: np.ndarray, t0: np.ndarray,
           t1: np.ndarray, v0: np.ndarray, v1: np.ndarray, nodes: np.ndarray, weights: np.ndarray,
           tolerance: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool]:
    """Gauss-Legendre integral of the pdf over rectangles [t0, t1] x [v0, v1] in (tau, v), where u =
    :func:`_u_of` (a, b, tau), over the support only (see :func:`integrate_bins`; the rectangles are
    :func:`_cut` already).  Returns, per rectangle, the integral, whether some node saw zero density,
    whether some node saw positive density and the largest node value; and whether every value was finite
    and non-negative."""
    rects = t0.size
    n = nodes.size
    line_t = (t0[:, None] + (t1 - t0)[:, None] * nodes[None, :]).ravel()
    line_rect = np.repeat(np.arange(rects), n)
    line_u, jacobian = _u_of(a[line_rect], b[line_rect], line_t)
    line_w = ((t1 - t0)[:, None] * weights[None, :]).ravel() * jacobian
    lv0, lv1 = v0[line_rect], v1[line_rect]
    if support is not None:  # segments of each line between the boundary's crossings, kept if inside
        sa, sb, seg_line = _split(lv0, lv1, support.line_roots(domain, line_u))
        inside = support.contains(domain.from_uv(line_u[seg_line], 0.5 * (sa + sb)))
        sa, sb, seg_line = sa[inside], sb[inside], seg_line[inside]
    else:
        sa, sb, seg_line = lv0, lv1, np.arange(line_u.size)
    segments = sa.size
    vv = sa[:, None] + (sb - sa)[:, None] * nodes[None, :]
    uu = np.repeat(line_u[seg_line], n)
    values = _evaluate(pdf, domain.from_uv(uu, vv.ravel())).reshape(segments, n)
    ok = bool(np.all(np.isfinite(values)) and not np.any(values < 0))
    seg_value = (values @ weights) * (sb - sa)
    if support is not None:
        # Segments shorter than half their rectangle (a thin support: a grazing triangle, a lens seen
        # edge-on) may never be cut by the quarters' midlines, so the rectangles' refinement would not
        # see their error: they are refined along v on their own.
        short = np.flatnonzero((sb - sa) < 0.5 * (lv1 - lv0)[seg_line])
        if short.size:
            refined, short_ok = _refine_segments(domain, pdf, line_u[seg_line[short]], sa[short], sb[short],
                                                 seg_value[short], nodes, weights, tolerance)
            seg_value[short] = refined
            ok &= short_ok
    line_value = np.bincount(seg_line, seg_value, minlength=line_u.size) * line_w
    integral = np.bincount(line_rect, line_value, minlength=rects)
    seg_rect = line_rect[seg_line]
    zero = np.bincount(seg_rect, (values == 0).sum(axis=1), minlength=rects) > 0
    positive = np.bincount(seg_rect, (values > 0).sum(axis=1), minlength=rects) > 0
    largest = np.zeros(rects)
    if segments:
        np.maximum.at(largest, seg_rect, np.where(np.isfinite(values), values, 0.0).max(axis=1))
    return integral, zero, positive, largest, ok


def integrate_bins(domain: Domain, pdf: Callable[[np.ndarray], np.ndarray], res: tuple[int, int], *,
                   support: Support | None = None, order: int = 5, tolerance: float = 1e-6, max_depth: int = 8,
                   max_rects: int = 400_000) -> tuple[np.ndarray, float, bool]:
    """Integral of ``pdf`` over every cell of ``domain`` (res_u x res_v), over ``support`` only if given.

    Adaptive Gauss-Legendre of ``order`` nodes per coordinate: a rectangle is
    split into four until its integral and the sum over its quarters agree
    within ``tolerance`` times the domain's integral times its share of the
    domain (so the total is good to about ``tolerance``; the default keeps
    the expected counts of a million samples within one), or ``max_depth``
    is reached, or the next level would evaluate more than ``max_rects``
    rectangles.

    With a support, each quadrature line of constant u is integrated between
    the boundary's crossings (:meth:`Support.line_roots`; segments much
    shorter than their rectangle, as in a thin sliver, are refined along v
    on their own), and rectangles are cut where the boundary crosses their
    edges v0 and v1 (:meth:`Support.edge_crossings`), so the integral is
    over the support only.  What remains non-smooth is the support's length
    along u: it has kinks at corners and square-root singularities where
    lines of constant u touch the boundary (a cone, a disk), and a density
    in (cos theta, phi) may have them at the poles.  So u is integrated in
    tau, with u = a + (b - a) sin^2(pi tau / 2) on every interval [a, b]
    between those points (:meth:`Support.breaks`) and the ends of the
    domain: sqrt(u - a) becomes analytic in tau, and quartering in tau
    grades the rectangles toward the singular points (in u, Gauss-Legendre
    next to such a point converges only as h^1.5, slower than a tolerance
    proportional to the rectangle's area can follow).  A density constant on
    the support then integrates exactly up to rounding (about 1e-12).

    Without a support, rectangles whose nodes see both zero and nonzero
    density (an edge of unknown shape) are refined to ``max_depth`` unless
    their share is below the tolerance; slivers of support narrower than the
    nodes' spacing can still be missed.

    Returns (integrals (res_u, res_v), error estimate (the sum of the
    differences between rectangles and their quarters), whether the pdf was
    finite and non-negative at every node).
    """
    if support is not None:
        support.check_domain(domain)
    res_u, res_v = int(res[0]), int(res[1])
    (ua, ub), (va, vb) = domain.u_range, domain.v_range
    iu, iv = np.meshgrid(np.arange(res_u), np.arange(res_v), indexing="ij")
    iu, iv = iu.ravel(), iv.ravel()
    u0, u1 = ua + (ub - ua) * iu / res_u, ua + (ub - ua) * (iu + 1) / res_u
    v0, v1 = va + (vb - va) * iv / res_v, va + (vb - va) * (iv + 1) / res_v
    breaks = support.breaks(domain) if support is not None else np.zeros(0)
    # Knots: the ends and the breaks, one of a cluster closer than rounding can tell apart.
    margin = 1e-12 * (ub - ua)
    inner = np.unique(breaks[(breaks > ua + margin) & (breaks < ub - margin)])
    inner = inner[np.concatenate(([True], np.diff(inner) > margin))] if inner.size else inner
    knots = np.concatenate(([ua], inner, [ub]))
    u0, u1, owner = _split(u0, u1, np.broadcast_to(knots, (u0.size, knots.size)))
    v0, v1 = v0[owner], v1[owner]
    interval = np.clip(np.searchsorted(knots, 0.5 * (u0 + u1)) - 1, 0, knots.size - 2)
    a, b = knots[interval], knots[interval + 1]
    t0, t1 = _tau_of(a, b, u0), _tau_of(a, b, u1)
    t0[u0 == a], t1[u1 == b] = 0.0, 1.0
    t0, t1, row = _cut(domain, support, a, b, t0, t1, v0, v1)
    owner, a, b, v0, v1 = owner[row], a[row], b[row], v0[row], v1[row]
    nodes, weights = np.polynomial.legendre.leggauss(order)
    nodes, weights = 0.5 * (nodes + 1.0), 0.5 * weights
    coarse, zero, positive, largest, ok = _rects(domain, pdf, support, a, b, t0, t1, v0, v1, nodes, weights,
                                                 tolerance)
    scale = max(abs(float(coarse.sum())), 1e-300)
    area_total = (ub - ua) * (vb - va)
    floor = 1e-4 * tolerance * scale / (res_u * res_v)
    total = np.zeros(res_u * res_v)
    error = 0.0
    for depth in range(max_depth + 1):
        count = t0.size
        tm, vm = 0.5 * (t0 + t1), 0.5 * (v0 + v1)
        quarters = [(t0, tm, v0, vm), (t0, tm, vm, v1), (tm, t1, v0, vm), (tm, t1, vm, v1)]
        q_t0, q_t1, q_v0, q_v1 = (np.concatenate([q[i] for q in quarters]) for i in range(4))
        q_a, q_b = np.tile(a, 4), np.tile(b, 4)
        q_t0, q_t1, row = _cut(domain, support, q_a, q_b, q_t0, q_t1, q_v0, q_v1)
        q_a, q_b, q_v0, q_v1 = q_a[row], q_b[row], q_v0[row], q_v1[row]
        parent = row % count
        parts, p_zero, p_positive, p_largest, p_ok = _rects(domain, pdf, support, q_a, q_b, q_t0, q_t1, q_v0, q_v1,
                                                            nodes, weights, tolerance)
        ok &= p_ok
        fine = np.bincount(parent, parts, minlength=count)
        diff = np.abs(fine - coarse)
        width = _u_of(a, b, t1)[0] - _u_of(a, b, t0)[0]
        area = width * (v1 - v0)
        # Each rectangle may miss its share of the tolerance, or a floor 1e-4 of a cell's share: rounding
        # makes tiny rectangles by the poles noisy beyond their share of a concentrated density's integral.
        allowed = np.maximum(tolerance * scale * area / area_total, floor)
        done = (diff <= allowed) | (width <= margin)  # slivers next to a knot: u itself is only so precise
        if support is None:  # an unknown edge in the rectangle: its quadrature cannot be trusted to converge
            edge = ((zero | (np.bincount(parent, p_zero, minlength=count) > 0))
                    & (positive | (np.bincount(parent, p_positive, minlength=count) > 0)))
            biggest = largest.copy()
            np.maximum.at(biggest, parent, p_largest)
            done &= ~(edge & (biggest * area > allowed))
        if depth == max_depth or 16 * np.count_nonzero(~done) > max_rects:
            done[:] = True
        np.add.at(total, owner[done], fine[done])
        error += float(diff[done].sum())
        if done.all():
            break
        pick = np.flatnonzero(~done[parent])
        owner, a, b = owner[parent[pick]], q_a[pick], q_b[pick]
        t0, t1, v0, v1 = q_t0[pick], q_t1[pick], q_v0[pick], q_v1[pick]
        coarse, zero, positive, largest = parts[pick], p_zero[pick], p_positive[pick], p_largest[pick]
    return total.reshape(res_u, res_v), error, ok


# -- the test -----------------------------------------------------------------------------------------


def _bin(domain: Domain, points: np.ndarray, res_u: int, res_v: int) -> tuple[np.ndarray, int]:
    """Counts of ``points`` per cell (res_u * res_v,), and how many fall beyond the domain."""
    u, v = domain.to_uv(points)
    (ua, ub), (va, vb) = domain.u_range, domain.v_range
    inside = (u >= ua) & (u <= ub) & (v >= va) & (v <= vb)
    iu = np.clip(((u[inside] - ua) / (ub - ua) * res_u).astype(np.int64), 0, res_u - 1)
    iv = np.clip(((v[inside] - va) / (vb - va) * res_v).astype(np.int64), 0, res_v - 1)
    return np.bincount(iu * res_v + iv, minlength=res_u * res_v).astype(np.float64), int((~inside).sum())


def _outside_support(domain: Domain, pdf: Callable, support: Support | None, points: np.ndarray,
                     edge_tolerance: float) -> np.ndarray:
    """Which points are outside the support: density zero (or excluded by ``support``) at the point and
    at its 8 neighbours ``edge_tolerance`` away (:meth:`SphereDomain.neighbours`,
    :meth:`PlaneDomain.neighbours`)."""
    def inside(x):
        with np.errstate(invalid="ignore"):
            keep = _evaluate(pdf, x) > 0          # NaN counts as outside; inf as inside
        if support is not None:
            keep &= support.contains(x)
        return keep

    outside = ~inside(points)
    if not outside.any() or edge_tolerance <= 0:
        return outside
    suspects = np.flatnonzero(outside)
    near = np.zeros(suspects.size, dtype=bool)
    for neighbour in domain.neighbours(points[:, suspects], edge_tolerance):
        near |= inside(neighbour)
    outside[suspects[near]] = False
    return outside


def _pearson(expected: np.ndarray, observed: np.ndarray) -> tuple[float, int]:
    """Pearson's statistic over categories, pooling the smallest expected counts until the pool expects
    MIN_EXPECTED.  Returns (statistic, degrees of freedom)."""
    used = (expected > 0) | (observed > 0)
    e, o = expected[used], observed[used]
    order = np.argsort(e, kind="stable")
    e, o = e[order], o[order]
    small = int(np.count_nonzero(e < MIN_EXPECTED))
    if small:
        reach = int(np.searchsorted(np.cumsum(e), MIN_EXPECTED)) + 1
        k = min(max(small, reach), e.size)
        e = np.append(e[k:], e[:k].sum())
        o = np.append(o[k:], o[:k].sum())
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = np.where(e > 0, (o - e) ** 2 / e, np.where(o > 0, np.inf, 0.0))
    return float(terms.sum()), e.size - 1


def chi2_test(domain: Domain, sample: Callable, pdf: Callable[[np.ndarray], np.ndarray], *, support: Support | None = None,
              integral: Callable | None = None, sample_count: int = 1_000_000, res: int | tuple | None = None,
              seed: int = 0, alpha: float = 0.01, test_count: int = 1, dims: int = 2, order: int = 5,
              tolerance: float = 1e-6, max_depth: int = 8, edge_tolerance: float = 1e-5,
              integral_tolerance: float = 1e-3) -> ChiSquareResult:
    """Test that ``sample`` draws points of ``domain`` with density ``pdf`` (in the domain's measure).

    ``sample(u)`` takes (dims, N) uniforms and returns points ((3, N) unit
    directions for a :class:`SphereDomain`, (2, N) for a :class:`PlaneDomain`)
    or (points, valid (N,) bool); invalid samples count toward N but land in
    no cell, so the density may integrate to less than one.  ``pdf(points)``
    returns (N,) densities.  ``support``: where the density is nonzero, if
    known exactly (see the module docstring); ``integral(u0, u1, v0, v1)``:
    the exact integral of the density over cells (arrays of their edges), if
    known, instead of quadrature.  ``res``: cells (res_u, res_v), or about
    that many cells if an int; by default about 200 expected samples per
    cell.  ``test_count``: the number of tests in the family, for Sidak's
    correction of ``alpha``.  ``order``, ``tolerance``, ``max_depth``: of
    the quadrature (:func:`integrate_bins`); ``edge_tolerance``: how far
    from the support a sample may lie and still count as inside (radians on
    the sphere, a fraction of the larger side in the plane);
    ``integral_tolerance``: how far above one the density's integral over
    the domain may be.  Choose a zoomed domain whose pole (its axis) is not
    on a thin feature: (cos theta, phi) cells are singular there, and a
    narrow ridge through the pole costs the quadrature deep refinement.
    """
    if support is not None:
        support.check_domain(domain)
    if res is None:
        res = domain.default_res(max(16, int(sample_count / 200)))
    elif np.isscalar(res):
        res = domain.default_res(int(res))
    res_u, res_v = int(res[0]), int(res[1])
    rng = np.random.default_rng(seed)
    out = sample(rng.random((dims, sample_count)))
    points, valid = out if isinstance(out, tuple) else (out, None)
    points = np.asarray(points)
    if points.shape != (domain.point_dims, sample_count):
        raise ValueError(f"sample: expected points of shape {(domain.point_dims, sample_count)} for {domain!r}, "
                         f"got {points.shape}")
    valid = np.ones(sample_count, bool) if valid is None else np.broadcast_to(np.asarray(valid, dtype=bool),
                                                                             (sample_count,))
    points = points[:, valid].astype(np.float64)
    finite = np.all(np.isfinite(points), axis=0)
    nonfinite = int((~finite).sum())
    points = points[:, finite]
    observed, beyond = _bin(domain, points, res_u, res_v)
    outside = int(_outside_support(domain, pdf, support, points, edge_tolerance).sum())

    if integral is not None:
        (ua, ub), (va, vb) = domain.u_range, domain.v_range
        iu, iv = np.meshgrid(np.arange(res_u), np.arange(res_v), indexing="ij")
        iu, iv = iu.ravel(), iv.ravel()
        cells = np.asarray(integral(ua + (ub - ua) * iu / res_u, ua + (ub - ua) * (iu + 1) / res_u,
                                    va + (vb - va) * iv / res_v, va + (vb - va) * (iv + 1) / res_v), dtype=np.float64)
        error, pdf_ok = 0.0, bool(np.all(np.isfinite(cells)) and not np.any(cells < 0))
    else:
        cells, error, pdf_ok = integrate_bins(domain, pdf, (res_u, res_v), support=support, order=order,
                                              tolerance=tolerance, max_depth=max_depth)
    cells = cells.ravel()
    expected = cells * sample_count
    pdf_integral = float(cells.sum())
    significance = sidak_significance(alpha, test_count)
    report = dict(observed=observed.reshape(res_u, res_v), expected=expected.reshape(res_u, res_v),
                  integral_error=error, outside=outside, outside_domain=beyond, nonfinite=nonfinite,
                  invalid=int(sample_count - valid.sum()), domain=repr(domain) + (f", {support!r}" if support else ""))

    if not pdf_ok or not np.all(np.isfinite(expected)) or np.any(expected < 0):
        reason = "the pdf is negative or not finite somewhere"
        return ChiSquareResult(False, np.inf, 0, 0.0, significance, pdf_integral, reason, **report, reasons=[reason])
    reasons = []
    if pdf_integral > 1.0 + integral_tolerance:
        reasons.append(f"the pdf integrates to {pdf_integral:.5f} > 1 over the domain")
    if outside:
        reasons.append(f"{outside} samples fell outside the support (where the pdf is zero)")
    if nonfinite:
        reasons.append(f"{nonfinite} valid samples are not finite")
    # Everything not in a cell -- invalid samples, samples beyond a zoomed domain -- is one more category.
    rest_expected = max(sample_count - float(expected.sum()), 0.0)
    rest_observed = sample_count - float(observed.sum())
    statistic, dof = _pearson(np.append(expected, rest_expected), np.append(observed, rest_observed))
    if dof < 1:
        reasons.append("too few populated cells for a test")
        return ChiSquareResult(False, np.inf, 0, 0.0, significance, pdf_integral, "; ".join(reasons), **report,
                               reasons=reasons)
    from scipy import stats  # here, not at module level: scipy.stats takes most of a second to import

    p_value = float(stats.chi2.sf(statistic, dof))
    if p_value < significance:
        reasons.append("samples are not distributed according to the pdf")
    message = "; ".join(reasons) if reasons else "samples are consistent with the pdf"
    return ChiSquareResult(not reasons, statistic, dof, p_value, significance, pdf_integral, message, **report,
                           reasons=reasons)


def chi2_test_directions(sample: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                         pdf: Callable[[np.ndarray], np.ndarray], *, sample_count: int = 1_000_000,
                         res_z: int | None = None, res_phi: int | None = None, seed: int = 0,
                         alpha: float = 0.01, test_count: int = 1, quadrature: int = 5, dims: int = 2,
                         support: Support | None = None, axis=(0.0, 0.0, 1.0), max_angle: float = np.pi,
                         **options) -> ChiSquareResult:
    """:func:`chi2_test` over the sphere of directions (solid-angle densities), or the cap of ``max_angle``
    about ``axis``, in res_z x res_phi equal-solid-angle cells.

    ``sample(u)`` takes (dims, N) uniforms and returns (directions (3, N),
    valid (N,) bool); ``pdf(directions)`` returns (N,) densities.
    """
    domain = SphereDomain(axis, max_angle)
    res = None
    if res_z is not None or res_phi is not None:
        auto = domain.default_res(max(16, int(sample_count / 200)))
        res = (res_z or auto[0], res_phi or 2 * (res_z or auto[0]))
    return chi2_test(domain, sample, pdf, support=support, sample_count=sample_count, res=res, seed=seed,
                     alpha=alpha, test_count=test_count, dims=dims, order=quadrature, **options)

