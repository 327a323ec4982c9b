"""The Metropolis kernel in primary sample space, tested on known targets.

* Each small-step kernel samples the density it states (chi-square), and n steps drawn at once (lazy
  catch-up) are distributed as n single steps (two-sample Kolmogorov-Smirnov).
* A catch-up of many steps: past the step size's limit (where the sum modulo 1 is within 1e-12 of
  uniform, from the kernel's Fourier coefficients) one uniform; longer ones summed in bounded chunks.
* Detailed balance f(x) T(x->y) a(x->y) = f(y) T(y->x) a(y->x) holds on sampled pairs of every mutation.
* Chains on a 2D target with a discontinuity, a peak and a number drawn only in half of the domain (lazy
  numbers) reproduce it (chi-square of the chains' states; each mutation alone and mixed), and so does
  the marginal of the lazily drawn number.
* The expected-value splats of the chains estimate the target's integral over each pixel.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import special, stats

from pathspace import _native
from pathspace.estimators.base import Counters
from pathspace.estimators.bootstrap import bootstrap
from pathspace.estimators.metropolis import Chains, Proposal, Target
from pathspace.estimators import primary
from pathspace.estimators.primary import (ChainStates, SmallStep, advance, exponential_catch_up_limit,
                                         film_position, new_counters)

ALPHA = 1e-3
STEPS = [SmallStep("exponential", 1 / 64), SmallStep("exponential", 0.2), SmallStep("gaussian", 0.01),
         SmallStep("gaussian", 0.2)]


def uniforms_of(seed: int, key: tuple = ()):
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=key))
    return lambda k: rng.random(k)


def streams_of(seed: int):
    """The bootstrap's random streams: one per key."""
    return lambda key: uniforms_of(seed, key)


def _wrap(x):
    """x mod 1 in [0, 1), a value rounding up to 1.0 becoming 0.0 (as ext/primary.c wraps a moved number)."""
    y = x - np.floor(x)
    return np.where(y >= 1.0, 0.0, y)


@pytest.mark.parametrize("step", STEPS, ids=lambda s: f"{s.kernel}-{s.size:g}")
@pytest.mark.parametrize("start", [0.5, 0.003])
def test_small_step_samples_its_density(step, start):
    n, bins, sub = 200_000, 400, 200
    y = _wrap(start + step.steps(np.ones(n, np.int64), uniforms_of(1)))
    fine = (np.arange(bins * sub) + 0.5) / (bins * sub)
    mass = step.pdf(np.full(fine.size, start), fine).reshape(bins, sub).mean(axis=1) / bins
    assert mass.sum() == pytest.approx(1.0, abs=2e-3)          # the stated density integrates to 1
    observed = np.histogram(y, np.linspace(0.0, 1.0, bins + 1))[0]
    keep = mass * n >= 5
    assert observed[~keep].sum() <= 3 * mass[~keep].sum() * n + 10
    chi2, p = stats.chisquare(observed[keep], mass[keep] / mass[keep].sum() * observed[keep].sum())
    assert p > ALPHA, (chi2, p)


@pytest.mark.parametrize("step", STEPS, ids=lambda s: f"{s.kernel}-{s.size:g}")
def test_catch_up_is_n_single_steps(step):
    n, count = 50_000, 7
    at_once = _wrap(0.5 + step.steps(np.full(n, count, np.int64), uniforms_of(2)))
    uniforms = uniforms_of(3)
    one_by_one = np.full(n, 0.5)
    for _ in range(count):
        one_by_one = _wrap(one_by_one + step.steps(np.ones(n, np.int64), uniforms))
    assert stats.ks_2samp(at_once, one_by_one).pvalue > ALPHA


def counting(seed: int):
    """A uniform source that counts the numbers it has drawn (``source.drawn``)."""
    rng = np.random.default_rng(seed)

    def source(k):
        source.drawn += k
        return rng.random(k)

    source.drawn = 0
    return source


def g(x):
    """phi(2 pi k) of the exponential kernel of size s2 = x / k: E[cos(2 pi x 16^-v)], v uniform."""
    return (special.sici(2 * np.pi * x)[1] - special.sici(2 * np.pi * x / 16)[1]) / np.log(16.0)


LIMITS = {0.25: 125, 1 / 16: 2042, 1 / 64: 33497, 0.01: 82416, 1e-3: 8567570}


@pytest.mark.parametrize("size", [0.25, 0.2, 0.1, 1 / 16, 1 / 32, 1 / 64, 0.01, 3e-3, 1e-3])
def test_catch_up_limit_makes_the_wrapped_sum_uniform(size):
    """At the limit, the sum of n exponential steps modulo 1 is within 1e-12 of uniform in total variation:
    TV <= 1/2 (2 sum_k>=1 phi(2 pi k)^(2n))^(1/2), summed with the exact phi (k beyond K: |phi| <= 17 / (pi k
    s2 log 16) < 1/4, negligible)."""
    limit = exponential_catch_up_limit(size)
    if size in LIMITS:
        assert limit == LIMITS[size]
    k = np.arange(1, int(np.ceil(4 * 17 / (np.pi * size * np.log(16.0)))) + 1)
    phi = g(k * size)
    assert np.abs(phi).max() == pytest.approx(g(size), rel=1e-12)   # rho is phi(2 pi)

    def bound(n):
        return 0.5 * np.sqrt(2 * np.sum(np.abs(phi) ** (2 * n)))

    assert bound(limit) <= 1e-12
    assert bound(int(0.8 * limit)) > 1e-12    # the limit is not wastefully large
    # TV >= |phi(2 pi)|^n / 2 (a Fourier coefficient of density - 1 is at most 2 TV): a quarter of the limit
    # is far from uniform, and a fixed 4096 steps is not enough from the default size 1/64 down.
    assert abs(phi[0]) ** (limit // 4) / 2 > 2e-4
    if size <= 1 / 64:
        assert abs(phi[0]) ** 4096 / 2 > 0.01


def test_rho_is_the_first_fourier_coefficient_for_every_step_size():
    """The limit's proof: |g(x)| <= g(1/4) = 0.800 for x >= 1/4 (checked on [1/4, 2.5]; beyond, the bound
    17 / (pi x log 16) < 0.8), and g decreases on (0, 1/4]."""
    x = np.linspace(0.25, 2.5, 200_001)
    assert g(0.25) == pytest.approx(0.800046, abs=1e-6)
    assert np.abs(g(x[1:])).max() < g(0.25)
    assert 17 / (np.pi * 2.5 * np.log(16.0)) < 0.8
    small = np.geomspace(1e-6, 0.25, 1000)
    assert np.all(np.diff(g(small)) < 0)


def test_a_huge_lag_draws_one_uniform_and_is_uniform():
    step = SmallStep()                                  # exponential, s2 = 1/64: the limit is 33497 steps
    limit = int(step.catch_up_limit)
    source = counting(4)
    n = 100_000
    y = _wrap(0.5 + step.steps(np.full(n, 10 ** 15, np.int64), source))
    assert source.drawn == n
    observed = np.histogram(y, np.linspace(0, 1, 101))[0]
    assert stats.chisquare(observed).pvalue > ALPHA
    source = counting(5)
    step.steps(np.array([limit - 1, limit, 10 ** 18, 0, 3]), source)
    assert source.drawn == 2 * (limit - 1) + 2 + 2 * 3
    # In a chain: 20000 numbers that missed 10^9 accepted small steps are fetched with 3 uniforms each
    # (one for the catch-up, two for the proposal's small step), and are uniform.
    chains = 20_000
    source = counting(6)
    counters = new_counters(chains)
    states = ChainStates(chains, step, source, counters)
    states.load(np.arange(chains), np.full((chains, 1), 0.5))
    counters["accepted"][:] = 10 ** 9
    source.drawn = 0
    states.fetch(np.arange(chains), np.zeros(chains, np.int64))
    assert source.drawn == 3 * chains
    current = states.numbers(np.arange(chains))[:, 0]
    assert stats.chisquare(np.histogram(current, np.linspace(0, 1, 51))[0]).pvalue > ALPHA


def test_chunked_catch_up_sums_each_numbers_own_steps(monkeypatch):
    """Catch-ups longer than CATCH_UP_CHUNK steps are summed chunk by chunk (numbers' steps straddle chunks,
    and one number spans several): every step is drawn once and added to its own number, in order."""
    monkeypatch.setattr(primary, "CATCH_UP_CHUNK", 5)
    step, rng, calls = SmallStep("exponential", 0.2), np.random.default_rng(8), []

    def source(k):
        calls.append(rng.random(k))
        return calls[-1]

    counts = np.array([7, 1, 12, 3, 0, 2, 9])
    at_once = step.steps(counts, source)
    assert [c.size for c in calls] == [10, 10, 10, 10, 10, 10, 8]       # 34 steps: 6 chunks of 5 and one of 4
    u = np.concatenate(calls).reshape(-1, 2).T                          # a pair per step: magnitude, sign
    single = 0.2 * 16.0 ** -u[0] * np.where(u[1] < 0.5, -1.0, 1.0)
    ends = np.cumsum(counts)
    expected = [single[end - count:end].sum() for count, end in zip(counts, ends)]
    np.testing.assert_allclose(at_once, expected, rtol=1e-12, atol=1e-15)


def test_steps_of_count_zero_do_not_move():
    step = SmallStep("exponential", 1 / 64)
    assert np.all(step.steps(np.zeros(5, np.int64), uniforms_of(0)) == 0.0)


# -- a 2D target with a lazily drawn third number ------------------------------------------------------

FILM = (8, 8)


def density(u0, u1):
    """The target's marginal over (u0, u1): a floor, a peak and a step (edges on 1/16 bins)."""
    peak = 5.0 * np.exp(-((u0 - 0.3) ** 2 + (u1 - 0.65) ** 2) / (2 * 0.08 ** 2))
    return 0.2 + peak + 2.0 * ((u0 >= 0.75) & (u1 < 0.25))


class Toy(Target):
    """f(u) = density(u0, u1), times (0.5 + u2) where u0 < 0.5 (u2 is drawn only there): its marginal over
    (u0, u1) is ``density``, and u2's conditional density where it is drawn is 0.5 + u2."""

    streams = ("camera",)
    film = FILM

    def evaluate(self, states, rows, labels, counters):
        s = states["camera"]
        u = s.fetch(np.repeat(rows, 2), np.tile(np.arange(2), rows.size)).reshape(-1, 2).T
        f = density(u[0], u[1])
        lazy = np.flatnonzero(u[0] < 0.5)
        f[lazy] *= 0.5 + s.fetch(rows.take(lazy), np.full(lazy.size, 2))
        return Proposal(np.arange(rows.size), film_position(u, FILM), np.repeat(f[None, :], 3, axis=0))


def run_toy(step: SmallStep, p_large: float, chains: int, steps: int, seed: int):
    uniforms = uniforms_of(seed, (1 << 20,))   # the chains' stream, apart from the bootstrap's
    contribution = lambda values: values[1]   # noqa: E731
    boot = bootstrap(Toy(), 1 << 16, chains, contribution, streams_of(seed), Counters())
    pixels = FILM[0] * FILM[1]
    chain = Chains(Toy(), contribution, step, p_large, uniforms, boot.label,
                   np.full(chains, pixels * boot.brightness[0] / chains), pixels, 3)
    chain.start(boot.numbers, Counters())
    image = np.zeros((3, pixels))
    for _ in range(steps):
        chain.step_all(image, Counters())
    chain.flush(image)
    return chain, image / steps, boot


def bin_masses(bins: int) -> np.ndarray:
    sub = 32
    grid = (np.arange(bins * sub) + 0.5) / (bins * sub)
    u0, u1 = np.meshgrid(grid, grid, indexing="ij")
    values = density(u0, u1).reshape(bins, sub, bins, sub).mean(axis=(1, 3))
    return values / values.sum()


MUTATIONS = [("small-exponential", SmallStep("exponential", 1 / 16), 0.0),
             ("small-gaussian", SmallStep("gaussian", 0.05), 0.0),
             ("large", SmallStep("exponential", 1 / 16), 1.0),
             ("mixture", SmallStep("exponential", 1 / 64), 0.3)]


@pytest.mark.parametrize("name,step,p_large", MUTATIONS, ids=[m[0] for m in MUTATIONS])
def test_chains_reproduce_a_2d_target(name, step, p_large):
    chains = 20_000
    chain, image, boot = run_toy(step, p_large, chains, 40, seed=5)
    u = chain.states["camera"].numbers(np.arange(chains))[:, :3]
    bins = 16
    observed = np.histogram2d(u[:, 0], u[:, 1], bins=bins, range=[[0, 1], [0, 1]])[0].ravel()
    expected = bin_masses(bins).ravel() * chains
    chi2, p = stats.chisquare(observed, expected)
    assert p > ALPHA / len(MUTATIONS), (chi2, p)
    # The lazily drawn number, where the chains' states use it: density 0.5 + u2.
    lazy = u[u[:, 0] < 0.5, 2]
    edges = np.linspace(0, 1, 11)
    expected_lazy = (0.5 * np.diff(edges) + 0.5 * np.diff(edges ** 2)) * lazy.size
    chi2, p = stats.chisquare(np.histogram(lazy, edges)[0], expected_lazy)
    assert p > ALPHA / len(MUTATIONS), (chi2, p)


def test_splats_estimate_the_pixel_integrals():
    """The image is P b E[V/f]: here each pixel's mean of the density (its integral times P)."""
    step = SmallStep("exponential", 1 / 16)
    images = np.stack([run_toy(step, 0.3, 4096, 64, seed=seed)[1][1] for seed in range(8)])
    mean, error = images.mean(axis=0), images.std(axis=0, ddof=1) / np.sqrt(images.shape[0])
    pixels = FILM[0] * FILM[1]
    truth = bin_masses(8).T.ravel() * pixels * density_integral()   # pixel index = row (u1) * width + column (u0)
    z = (mean - truth) / error
    critical = stats.t.isf(ALPHA / (2 * pixels), images.shape[0] - 1)
    assert np.abs(z).max() < critical, np.abs(z).max()


def density_integral() -> float:
    grid = (np.arange(1024) + 0.5) / 1024
    u0, u1 = np.meshgrid(grid, grid, indexing="ij")
    return float(density(u0, u1).mean())


@pytest.mark.parametrize("step", STEPS[:3], ids=lambda s: f"{s.kernel}-{s.size:g}")
@pytest.mark.parametrize("large", [False, True])
def test_detailed_balance_on_sampled_pairs(step, large):
    """f(x) T(x->y) a(x->y) = f(y) T(y->x) a(y->x) for proposals y of states x, with T the product of the
    per-number step densities (a large step: T = 1 both ways); every proposal lies in T's support."""
    n, dims = 5000, 4
    uniforms = uniforms_of(7)
    counters = new_counters(n)
    states = ChainStates(n, step, uniforms, counters)
    states.load(np.arange(n), uniforms(n * dims).reshape(n, dims))
    counters["large"][:] = large
    rows, columns = np.repeat(np.arange(n), dims), np.tile(np.arange(dims), n)
    y = states.fetch(rows, columns).reshape(n, dims)
    x = states.numbers(np.arange(n))[:, :dims]

    def f(u):
        return density(u[:, 0], u[:, 1]) * (0.5 + u[:, 2]) * (1.0 + u[:, 3] ** 2)

    def transition(a, b):
        return np.ones(n) if large else np.prod(step.pdf(a, b), axis=1)

    forward, backward = transition(x, y), transition(y, x)
    assert np.all(forward > 0)
    accept_fwd, accept_back = np.minimum(1, f(y) / f(x)), np.minimum(1, f(x) / f(y))
    np.testing.assert_allclose(f(x) * forward * accept_fwd, f(y) * backward * accept_back, rtol=1e-12)


def test_rejected_proposals_keep_the_state_and_accepted_ones_take_it():
    n = 64
    uniforms = uniforms_of(11)
    counters = new_counters(n)
    states = ChainStates(n, SmallStep(), uniforms, counters)
    start = uniforms(n * 3).reshape(n, 3)
    states.load(np.arange(n), start)
    y = states.fetch(np.repeat(np.arange(n), 3), np.tile(np.arange(3), n)).reshape(n, 3)
    accept = np.arange(n) % 2 == 0
    states.settle(accept)
    advance(counters, accept)
    current = states.numbers(np.arange(n))[:, :3]
    np.testing.assert_array_equal(current[accept], y[accept])
    np.testing.assert_array_equal(current[~accept], start[~accept])
    assert np.all(np.isnan(states.numbers(np.arange(n), proposal=True)))


def test_fresh_states_serve_the_stream_s_uniforms_and_clear_what_they_drew():
    """The bootstrap's independent samples: numbers not given are the next uniforms of the stream, in the order
    they are asked for; clearing forgets every number drawn or given."""
    n, k = 64, 60
    states = ChainStates(n, None, uniforms_of(12), fresh=True)
    states.set_proposal(0, np.full(k, 0.5))
    rows, columns = np.repeat(np.arange(k), 40), np.tile(np.arange(40), k)   # past the stored width
    drawn = states.fetch(rows, columns).reshape(k, 40)
    assert np.all(drawn[:, 0] == 0.5)
    np.testing.assert_array_equal(drawn[:, 1:].ravel(), uniforms_of(12)(k * 39))
    np.testing.assert_array_equal(states.numbers(np.arange(k), proposal=True)[:, :40], drawn)
    states.clear()
    assert np.isnan(states.proposal).all() and states.current is None


# -- the C kernels against a number-by-number reference ---------------------------------------------------

def reference_fetch(states: ChainStates, rows, columns, uniforms):
    """ChainStates.fetch number by number in NumPy (the order ext/primary.c draws in), on copies of the state:
    (numbers, flat indices drawn, proposal, current, stamp)."""
    proposal, current, stamp = (None if a is None else a.copy() for a in (states.proposal, states.current,
                                                                           states.stamp))
    c, step, out, drawn = states.counters, states.step, [], []
    for r, col in zip(rows, columns):
        if not np.isnan(proposal[col, r]):
            out.append(proposal[col, r])
            continue
        if states.fresh or (not states.replay and c["large"][r]):
            value = uniforms(1)[0]
        else:
            x, accepted = current[col, r], c["accepted"][r]
            if stamp[col, r] < c["last_large"][r]:
                x = uniforms(1)[0]
            elif stamp[col, r] < accepted:
                x = _wrap(x + step.steps(np.array([accepted - stamp[col, r]]), uniforms)[0])
            current[col, r], stamp[col, r] = x, accepted
            value = x if states.replay else _wrap(x + step.single(1, uniforms)[0])
        proposal[col, r] = value
        out.append(value)
        drawn.append(col * states.chains + r)
    return np.array(out), np.array(drawn, np.int64), proposal, current, stamp


def random_states(seed: int, step: SmallStep | None, chains: int = 40, width: int = 12, lag: int = 300,
                  fresh: bool = False) -> ChainStates:
    """States with numbers at every stage: drawn by the proposal or not, never drawn, replaced by an accepted
    large step since, missing up to ``lag`` accepted small steps; chains on large or small steps."""
    rng = np.random.default_rng(seed)
    states = ChainStates(chains, step, uniforms_of(seed, (1,)), width=width, fresh=fresh)
    states.proposal[...] = np.where(rng.random((width, chains)) < 0.3, rng.random((width, chains)), np.nan)
    c = states.counters
    c["accepted"][:] = rng.integers(0, lag, chains)
    c["last_large"][:] = (c["accepted"] * rng.random(chains) ** 4).astype(np.int64)
    c["large"][:] = rng.random(chains) < 0.3
    if not fresh:
        states.current[...] = rng.random((width, chains))
        states.stamp[...] = np.minimum(rng.integers(-1, lag, (width, chains)), c["accepted"])
    return states


def some_numbers(seed: int, chains: int, width: int, k: int):
    """k distinct (row, column) pairs of the stored state, in a random order."""
    cells = np.random.default_rng(seed).permutation(chains * width)[:k]
    return cells % chains, cells // chains


@pytest.mark.parametrize("step", STEPS + [SmallStep("exponential", 0.25)], ids=lambda s: f"{s.kernel}-{s.size:g}")
@pytest.mark.parametrize("mode", ["chain", "replay", "fresh"])
def test_fetch_kernel_draws_each_number_as_the_reference(step, mode):
    """primary_fetch against the number-by-number reference: the same numbers (to rounding: C's and NumPy's exp,
    log1p and cos), the same state afterwards, the same flat indices drawn, and the stream left at the same
    place.  Exponential steps of 1/4 have a catch-up limit of 125 steps, so lags of up to 300 cross it."""
    states = random_states(20, None if mode == "fresh" else step, fresh=mode == "fresh")
    states.replay = mode == "replay"
    rows, columns = some_numbers(21, states.chains, states.width, 400)
    reference = uniforms_of(20, (1,))
    expected, drawn, proposal, current, stamp = reference_fetch(states, rows, columns, reference)
    got = states.fetch(rows, columns)
    np.testing.assert_allclose(got, expected, rtol=1e-13, atol=1e-15)
    assert np.all((got >= 0.0) & (got < 1.0))
    np.testing.assert_array_equal(np.concatenate(states.drawn), drawn)
    np.testing.assert_allclose(states.proposal, proposal, rtol=1e-13, atol=1e-15, equal_nan=True)
    if mode != "fresh":
        np.testing.assert_allclose(states.current[:current.shape[0]], current, rtol=1e-13, atol=1e-15)
        np.testing.assert_array_equal(states.stamp[:stamp.shape[0]], stamp)
    assert states.uniforms(1)[0] == reference(1)[0]   # both consumed the same count
    assert 0 < drawn.size < rows.size


def lagging_states(seed: int, step: SmallStep, accepted) -> ChainStates:
    """Chains on small steps, one number each, last brought up to date at 0 accepted steps and since missing
    ``accepted[i]`` of them (no large step accepted); the proposal has drawn nothing."""
    states = random_states(seed, step, chains=len(accepted), width=1)
    states.proposal[...], states.stamp[...] = np.nan, 0
    states.counters["large"][:], states.counters["last_large"][:] = False, 0
    states.counters["accepted"][:] = accepted
    return states


def counted_draws(states: ChainStates, source) -> list[int]:
    """Serve ``states``' uniforms from ``source``, recording the size of each draw in the returned list."""
    calls: list[int] = []
    states.uniforms = lambda k: calls.append(k) or source(k)
    return calls


def test_fetch_kernel_draws_long_catch_ups_in_chunks():
    """A call needing more than 2^20 uniforms (exponential steps of 1/1000: limit 8.6e6 steps; lags of 3e5 to
    6e5) draws them chunk by chunk with the same result."""
    states = lagging_states(22, SmallStep("exponential", 1e-3), np.random.default_rng(22).integers(300_000,
                                                                                                   600_000, 6))
    calls = counted_draws(states, uniforms_of(22, (1,)))
    rows, columns = np.arange(6), np.zeros(6, np.int64)
    expected = reference_fetch(states, rows, columns, uniforms_of(22, (1,)))[0]
    np.testing.assert_allclose(states.fetch(rows, columns), expected, rtol=1e-10)
    assert len(calls) > 1 and max(calls) == 1 << 20 and sum(calls) == 2 * states.counters["accepted"].sum() + 12


def test_fetch_kernel_catches_up_at_the_limit():
    """Lags of limit - 1 steps are summed (2 uniforms a step), lags of limit and limit + 1 are one uniform."""
    step = SmallStep("exponential", 0.25)
    limit = int(step.catch_up_limit)
    states = lagging_states(27, step, [limit - 1, limit, limit + 1])
    calls = counted_draws(states, uniforms_of(27, (1,)))
    rows, columns = np.arange(3), np.zeros(3, np.int64)
    expected = reference_fetch(states, rows, columns, uniforms_of(27, (1,)))[0]
    np.testing.assert_allclose(states.fetch(rows, columns), expected, rtol=1e-13)
    assert calls == [2 * (limit - 1) + 2 + (1 + 2) + (1 + 2)]


@pytest.mark.parametrize("chains", [40, 49, 1000003])
def test_settle_kernel_takes_accepted_numbers_and_forgets_the_proposal(chains):
    """Also at chain counts whose flat indices test the settle's remainder without a division (49: 49, 98, ...
    sit where a quotient rounded up would read accept[-1])."""
    states = random_states(23, SmallStep(), chains=chains, width=12 if chains < 1000 else 2)
    rows, columns = some_numbers(24, states.chains, states.width, min(300 * chains // 40, 200_000))
    states.fetch(rows, columns)
    proposal, current, stamp = states.proposal.copy(), states.current.copy(), states.stamp.copy()
    flat = np.concatenate(states.drawn)
    accept = np.random.default_rng(25).random(states.chains) < 0.5
    states.settle(accept)
    taken = flat[accept[flat % states.chains]]
    current.reshape(-1)[taken] = proposal.reshape(-1)[taken]
    stamp.reshape(-1)[taken] = states.counters["accepted"][taken % states.chains] + 1
    proposal.reshape(-1)[flat] = np.nan
    np.testing.assert_array_equal(states.current, current)
    np.testing.assert_array_equal(states.stamp, stamp)
    np.testing.assert_array_equal(states.proposal, proposal)
    assert states.drawn == []


def test_primary_kernels_refuse_bad_arguments():
    states = random_states(26, SmallStep())
    c = states.counters
    args = lambda rows, columns, draw=states.uniforms: (states.proposal, states.current, states.stamp,  # noqa: E731
                                                       rows, columns, c["accepted"], c["last_large"], c["large"],
                                                       0, 0, 1 / 64, 33497.0, draw)
    one = np.zeros(1, np.int64)
    with pytest.raises(IndexError, match=r"outside the \(12, 40\) state"):
        _native.primary_fetch(*args(one + 40, one))
    with pytest.raises(IndexError, match="outside"):
        _native.primary_fetch(*args(one, one - 1))
    with pytest.raises(TypeError, match="rows must be a 1D int64"):
        _native.primary_fetch(*args(one.astype(np.int32), one))
    with pytest.raises(ValueError, match="columns must have length 1"):
        _native.primary_fetch(*args(one, np.zeros(2, np.int64)))
    states.proposal[5, 0], c["large"][0] = np.nan, True                   # a large step: one uniform
    with pytest.raises(ValueError, match=r"draw\(1\) must return 1 uniforms"):
        _native.primary_fetch(*args(one, one + 5, lambda k: np.zeros(k - 1)))
    with pytest.raises(TypeError, match="draw must be callable"):
        _native.primary_fetch(*args(one, one, None))
    with pytest.raises(ValueError, match="accepted must have length 40"):
        _native.primary_fetch(states.proposal, states.current, states.stamp, one, one, c["accepted"][:3],
                              c["last_large"], c["large"], 0, 0, 1 / 64, 1e4, states.uniforms)
    with pytest.raises(ValueError, match="same"):
        _native.primary_fetch(states.proposal, states.current[:3], states.stamp, one, one, c["accepted"],
                              c["last_large"], c["large"], 0, 0, 1 / 64, 1e4, states.uniforms)
    with pytest.raises(IndexError, match="flat\\[1\\] is outside the state of 480 numbers"):
        _native.primary_settle(states.proposal, states.current, states.stamp, np.array([0, 480]),
                               np.ones(40, bool), c["accepted"])


def test_fetch_kernel_failures_leave_no_number_drawn():
    """A pair asked for twice, a draw() that raises (here in the second chunk of a long catch-up) and a state
    changed during the call (so pass 1's count of uniforms no longer holds) are errors, and the proposal keeps
    none of the numbers the call drew."""
    states = random_states(28, SmallStep(), chains=8, width=3)
    states.proposal[...] = np.nan
    with pytest.raises(ValueError, match=r"\(rows, columns\)\[2\] asks again"):
        states.fetch(np.array([0, 1, 0]), np.array([2, 2, 2]))
    assert np.isnan(states.proposal).all() and states.drawn == []

    long = lagging_states(29, SmallStep("exponential", 1e-3), [500_000] * 4)
    source = uniforms_of(29, (1,))

    def failing(k):
        if len(calls) == 2:
            raise KeyError("no more numbers")
        return source(k)

    calls = counted_draws(long, failing)
    with pytest.raises(KeyError, match="no more numbers"):
        long.fetch(np.arange(4), np.zeros(4, np.int64))
    assert np.isnan(long.proposal).all() and long.drawn == [] and len(calls) == 2

    changed = random_states(30, SmallStep(), chains=8, width=1)
    changed.proposal[...], changed.counters["large"][:] = np.nan, True   # pass 1 counts one uniform each

    def shifting(k):
        changed.counters["large"][:] = False   # pass 2 then needs small steps: more uniforms than counted
        return uniforms_of(30)(k)

    changed.uniforms = shifting
    with pytest.raises(RuntimeError, match="state changed during the call"):
        changed.fetch(np.arange(8), np.zeros(8, np.int64))
    assert np.isnan(changed.proposal).all()


def test_a_step_that_rounds_up_to_one_wraps_to_zero():
    """0 moved by a Gaussian step of -1e-17 is 1 - 1e-17 modulo 1, which rounds to 1.0: it must come back as
    0.0, inside [0, 1)."""
    step = SmallStep("gaussian", 0.01)
    states = ChainStates(1, step, lambda k: np.array([0.5, 0.25 + 2.0 ** -54])[:k])
    states.load(np.zeros(1, np.int64), np.zeros((1, 1)))
    moved = step.single(1, lambda k: np.array([0.5, 0.25 + 2.0 ** -54]))[0]
    assert -1e-16 < moved < 0.0 and 0.0 + moved - np.floor(moved) == 1.0
    assert states.fetch(np.zeros(1, np.int64), np.zeros(1, np.int64))[0] == 0.0


def test_chain_states_need_a_step_and_writeable_arrays():
    with pytest.raises(ValueError, match="chains need a small step"):
        ChainStates(4, None, uniforms_of(0))
    states = random_states(31, SmallStep(), chains=4, width=2)
    c = states.counters
    args = [states.proposal, states.current, states.stamp, np.zeros(1, np.int64), np.zeros(1, np.int64),
            c["accepted"], c["last_large"], c["large"], 0, 0, 1 / 64, 33497.0, states.uniforms]
    frozen = states.proposal.copy()
    frozen.flags.writeable = False
    with pytest.raises(ValueError, match="proposal must be writeable"):
        _native.primary_fetch(frozen, *args[1:])
    for at, value, message in [(10, np.nan, "size must be finite"), (11, np.nan, "limit at least 1"),
                               (11, 0.5, "limit at least 1")]:
        with pytest.raises(ValueError, match=message):
            _native.primary_fetch(*args[:at], value, *args[at + 1:])
    states.proposal[0, 0], c["large"][0] = np.nan, True
    with pytest.raises(ValueError, match=r"draw\(1\) must return 1 uniforms as a 1-D float64 array"):
        _native.primary_fetch(*args[:-1], lambda k: np.ones(k, np.int64))
    assert np.isnan(states.proposal[0, 0])


class Broken(Toy):
    """The toy target with a NaN in every seventh lane's contribution."""

    def evaluate(self, states, rows, labels, counters):
        proposal = super().evaluate(states, rows, labels, counters)
        proposal.value[:, ::7] = np.nan
        return proposal


def test_nonfinite_contributions_are_dropped_and_counted():
    uniforms, step, counters = uniforms_of(13, (1 << 20,)), SmallStep(), Counters()
    contribution = lambda values: values[1]   # noqa: E731
    boot = bootstrap(Broken(), 4096, 256, contribution, streams_of(13), counters)
    chain = Chains(Broken(), contribution, step, 0.3, uniforms, boot.label, np.ones(256), 64, 3)
    chain.start(boot.numbers, counters)
    image = np.zeros((3, 64))
    for _ in range(5):
        chain.step_all(image, counters)
    chain.flush(image)
    assert np.isfinite(image).all() and image.sum() > 0
    assert np.isfinite(boot.brightness).all()
    assert counters.nonfinite_contributions >= (4096 + 6 * 256) // 7
