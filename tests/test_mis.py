"""Multiple importance sampling (pathspace.mis): the path tracer's two-strategy weights (ratio form,
zero-pdf strategies, partition of unity over 600 decades) and the BDPT kernel over all (s, t) strategies
(C against the NumPy reference, partition of unity over feasible strategies, infeasible strategies,
exponent bookkeeping beyond the double range, scale invariance, bad batches) and MIS over a subset of the
strategies (renormalised over the subset; one strategy equals mis="single")."""
from __future__ import annotations

import numpy as np
import pytest

from pathspace.mis import (LIGHT_DELTA, LIGHT_INFINITE, Connections, StrategySubset, SubpathPdfs, mis_weight,
                           mis_weights, mis_weights_reference)

# -- two strategies (the path tracer) ------------------------------------------------------------------


@pytest.mark.parametrize("heuristic, beta", [("balance", 1.0), ("power", 2.0), ("power", 3.5)])
def test_weights_sum_to_one_over_many_decades(heuristic, beta):
    rng = np.random.default_rng(0)
    a = 10.0 ** rng.uniform(-300, 300, 100_000)
    b = 10.0 ** rng.uniform(-300, 300, 100_000)
    wa, wb = mis_weight(a, b, heuristic, beta), mis_weight(b, a, heuristic, beta)
    np.testing.assert_allclose(wa + wb, 1.0, rtol=1e-12)
    assert np.all((wa >= 0) & (wa <= 1))
    # Against the textbook formula where it does not overflow.
    ok = (np.abs(np.log10(a)) < 50) & (np.abs(np.log10(b)) < 50)
    textbook = a[ok] ** beta / (a[ok] ** beta + b[ok] ** beta) if heuristic == "power" else a[ok] / (a[ok] + b[ok])
    np.testing.assert_allclose(wa[ok], textbook, rtol=1e-10, atol=1e-300)


def test_strategies_that_cannot_sample_get_zero_weight():
    w = mis_weight(np.array([0.0, 1.0, 0.0, np.inf]), np.array([1.0, 0.0, 0.0, 1.0]))
    np.testing.assert_array_equal(w, [0.0, 1.0, 0.0, 1.0])
    assert mis_weight(np.float64(2.0), np.float64(1.0)) == pytest.approx(0.8)
    with pytest.raises(ValueError, match="MIS heuristic"):
        mis_weight(np.ones(1), np.ones(1), "maximum")



# -- all (s, t) strategies (BDPT) ----------------------------------------------------------------------


def random_path(rng, k, delta_rate=0.25):
    """A path x_0 .. x_k: light-side and camera-side densities over many decades, random delta vertices."""
    p_light = 10.0 ** rng.uniform(-150, 150, k + 1)
    p_eye = 10.0 ** rng.uniform(-150, 150, k + 1)
    delta = rng.random(k + 1) < delta_rate
    delta[0] = delta[k] = False  # light and camera vertices are never specular
    p_light[delta] = 0.0         # delta vertices carry no density (remapped to 1 by the kernel)
    p_eye[delta] = 0.0
    return p_light, p_eye, delta


def strategy_batch(paths, heuristic_target=None):
    """Every strategy s = 0 .. k+1 of every path, as connections over per-(path, s) lanes."""
    rows, light_fwd, light_rev, light_delta, eye_fwd, eye_rev, eye_delta = [], [], [], [], [], [], []
    light_offset, eye_offset = [0], [0]
    lane_light_flags = []
    for path_index, (p_l, p_e, delta, light_flags) in enumerate(paths):
        k = len(p_l) - 1
        for s in range(k + 2):
            t = k + 1 - s
            lane = len(light_offset) - 1
            # Light subpath: x_0 .. x_{s-1}; eye subpath: x_k .. x_s (eye vertex j is path vertex k - j).
            light_fwd += list(p_l[:s]); light_rev += list(p_e[:s]); light_delta += list(delta[:s])
            eye_fwd += list(p_e[::-1][:t]); eye_rev += list(p_l[::-1][:t]); eye_delta += list(delta[::-1][:t])
            light_offset.append(len(light_fwd)); eye_offset.append(len(eye_fwd))
            lane_light_flags.append(light_flags)  # one connection per lane here
            get = lambda a, i: a[i] if 0 <= i <= k else 0.0
            rows.append((path_index, s, t, lane, get(p_l, s - 1), get(p_e, s - 1), get(p_e, s - 2),
                         get(p_e, s), get(p_l, s), get(p_l, s + 1)))
    rows = np.array(rows, dtype=np.float64)
    connections = Connections(rows[:, 1].astype(np.int32), rows[:, 2].astype(np.int32), rows[:, 3].astype(np.int64),
                              *rows[:, 4:].T)
    light = SubpathPdfs(np.array(light_offset), np.array(light_fwd), np.array(light_rev), np.array(light_delta))
    eye = SubpathPdfs(np.array(eye_offset), np.array(eye_fwd), np.array(eye_rev), np.array(eye_delta))
    return rows[:, 0].astype(int), connections, light, eye, np.array(lane_light_flags)


def feasible(path, s, camera_is_delta):
    """Whether strategy s can produce the path: s = 0 needs a light that can be hit, t = 0 a camera that
    can be hit, (1, 1) a light at a finite point; every other connection two non-delta vertices."""
    p_l, p_e, delta, light_flags = path
    k = len(p_l) - 1
    if s == 0:
        return not light_flags & LIGHT_DELTA
    if s == k + 1:
        return not camera_is_delta
    if s == 1 and k == 1 and light_flags & LIGHT_INFINITE:
        return False
    return not delta[s - 1] and not delta[s]


def random_flags(rng):
    """Light flags: mostly an area light; sometimes delta (point), infinite (environment) or both (directional)."""
    return int(rng.choice([0, LIGHT_DELTA, LIGHT_INFINITE, LIGHT_DELTA | LIGHT_INFINITE], p=[0.6, 0.15, 0.15, 0.1]))


@pytest.mark.parametrize("heuristic, beta", [("balance", 1.0), ("power", 2.0), ("power", 3.0), ("uniform", 1.0)])
@pytest.mark.parametrize("camera_is_delta", [False, True], ids=["thin-lens", "pinhole"])
def test_weights_partition_unity_over_feasible_strategies(heuristic, beta, camera_is_delta):
    rng = np.random.default_rng(7)
    paths = []
    for _ in range(400):
        k = int(rng.integers(1, 12)) if rng.random() < 0.9 else int(rng.integers(100, 260))
        p_l, p_e, delta = random_path(rng, k)
        paths.append((p_l, p_e, delta, random_flags(rng)))
    owner, connections, light, eye, light_flags = strategy_batch(paths)
    w = mis_weights(connections, light, eye, light_flags, camera_is_delta, heuristic, beta)
    assert np.all(np.isfinite(w)) and np.all((w >= 0) & (w <= 1))
    for index, path in enumerate(paths):
        mine = owner == index
        ok = np.array([feasible(path, s, camera_is_delta) for s in connections.s[mine]])
        if ok.any():
            assert abs(w[mine][ok].sum() - 1.0) < 1e-9, (index, w[mine])
        assert np.all(w[mine][~ok] == 0.0)
        if heuristic == "uniform" and ok.any():
            np.testing.assert_allclose(w[mine][ok], 1.0 / ok.sum(), rtol=1e-12)


@pytest.mark.parametrize("heuristic, beta", [("balance", 1.0), ("power", 2.0), ("power", 2.5), ("uniform", 1.0),
                                             ("single", 1.0), ("none", 1.0)])
@pytest.mark.parametrize("decades", [3, 150], ids=["moderate", "extreme"])
def test_c_kernel_matches_the_numpy_reference(heuristic, beta, decades):
    """Moderate densities take the kernel's plain-multiply path, extreme ones its exponent bookkeeping."""
    rng = np.random.default_rng(11)
    paths = []
    for _ in range(150):
        p_l, p_e, delta = random_path(rng, int(rng.integers(1, 9)))
        paths.append((p_l ** (decades / 150), p_e ** (decades / 150), delta, random_flags(rng)))
    owner, connections, light, eye, light_flags = strategy_batch(paths)
    args = (connections, light, eye, light_flags, False, heuristic, beta, (2, 3))
    fast, slow = mis_weights(*args), mis_weights_reference(*args)
    np.testing.assert_allclose(fast, slow, rtol=1e-12, atol=0)


@pytest.mark.parametrize("heuristic, beta", [("balance", 1.0), ("power", 2.0), ("power", 2.5)])
def test_ratios_that_pass_beyond_the_double_range_and_come_back(heuristic, beta):
    """Ratio products that climb past 1e240 (or fall below 1e-240) over one subpath and return to O(1):
    specular vertices in between make the strategies there infeasible, so only the end strategies
    (s = 0, 1, k, k + 1) count and their weights are far from 0 and 1 -- the kernel must leave its
    plain-multiply path and carry the exponent to get them right."""
    rng = np.random.default_rng(5)
    k = 12
    paths = []
    for sign in (1, -1) * 20:
        p_l, p_e = np.ones(k + 1), np.ones(k + 1)
        delta = np.zeros(k + 1, bool)
        delta[2:k:2] = True
        p_l[delta] = p_e[delta] = 0.0
        exponents = sign * np.array([80, 80, 80, -80, -80, -80])
        p_l[1:k:2] = 10.0 ** exponents * rng.uniform(0.5, 2.0, 6)
        p_l[[0, k]], p_e[[0, k]] = rng.uniform(0.5, 2.0, 2), rng.uniform(0.5, 2.0, 2)
        paths.append((p_l, p_e, delta, 0))
    owner, connections, light, eye, light_flags = strategy_batch(paths)
    args = (connections, light, eye, light_flags, False, heuristic, beta)
    fast, slow = mis_weights(*args), mis_weights_reference(*args)
    np.testing.assert_allclose(fast, slow, rtol=1e-12, atol=0)
    ends = np.isin(connections.s, [0, 1, k, k + 1])
    assert np.all(fast[~ends] == 0.0) and np.all((fast[ends] > 1e-6) & (fast[ends] < 1 - 1e-6))
    for index in range(len(paths)):
        assert abs(fast[owner == index].sum() - 1.0) < 1e-9


def test_scale_invariance_of_ratios():
    """Scaling every density by the same factor (a scene scaled by 1/sqrt(factor)) leaves every weight unchanged."""
    rng = np.random.default_rng(3)
    paths = [(*random_path(rng, 6, delta_rate=0.1), 0) for _ in range(50)]
    owner, connections, light, eye, light_flags = strategy_batch(paths)
    base = mis_weights(connections, light, eye, light_flags, False)
    for factor in (1e-12, 1e12):
        scaled = lambda x: x * factor
        c2 = Connections(connections.s, connections.t, connections.lane,
                         *(scaled(getattr(connections, f)) for f in ("qs_fwd", "qs_rev", "qs_minus_rev", "pt_fwd",
                                                                       "pt_rev", "pt_minus_rev")))
        l2 = SubpathPdfs(light.offset, scaled(light.fwd), scaled(light.rev), light.delta)
        e2 = SubpathPdfs(eye.offset, scaled(eye.fwd), scaled(eye.rev), eye.delta)
        np.testing.assert_allclose(mis_weights(c2, l2, e2, light_flags, False), base, rtol=1e-12)


def test_bad_batches_are_rejected():
    rng = np.random.default_rng(0)
    owner, connections, light, eye, light_flags = strategy_batch([(*random_path(rng, 3), False)])
    connections.s[0] = 40
    with pytest.raises(ValueError, match="does not fit its subpaths"):
        mis_weights(connections, light, eye, light_flags, False)
    with pytest.raises(KeyError):
        mis_weights(connections, light, eye, light_flags, False, "maximum")



# -- MIS over a subset of the strategies ---------------------------------------------------------------

SUBSETS = ["s != 0 and t != 0", "s >= 1", "t != 0", "k <= 3 or s == 1", [(1, 1), (2, 1), (1, 2), (0, 2), (0, 3)]]


def random_paths(rng, count, longest=9):
    return [(*random_path(rng, int(rng.integers(1, longest))), random_flags(rng)) for _ in range(count)]


@pytest.mark.parametrize("heuristic, beta", [("balance", 1.0), ("power", 2.0), ("uniform", 1.0)])
@pytest.mark.parametrize("spec", SUBSETS, ids=["no-s0-t0", "s>=1", "t!=0", "short-or-s1", "pairs"])
def test_subset_weights_partition_unity_over_the_feasible_strategies_of_the_subset(heuristic, beta, spec):
    rng = np.random.default_rng(21)
    paths = random_paths(rng, 300)
    owner, connections, light, eye, light_flags = strategy_batch(paths)
    subset = StrategySubset(spec)
    args = (connections, light, eye, light_flags, False, heuristic, beta)
    w = mis_weights(*args, subset=subset)
    np.testing.assert_allclose(w, mis_weights_reference(*args, subset=subset), rtol=1e-12, atol=0)
    inside = subset.table(64)[connections.s, connections.t].astype(bool)
    assert np.all(w[~inside] == 0.0)
    covered = 0
    for index, path in enumerate(paths):
        mine = owner == index
        ok = np.array([feasible(path, s, False) for s in connections.s[mine]]) & inside[mine]
        if ok.any():
            covered += 1
            assert abs(w[mine][ok].sum() - 1.0) < 1e-9, (index, w[mine])
        assert np.all(w[mine][~ok] == 0.0)
    assert covered > 50  # the test looked at paths (the pairs cover paths of 1 and 2 segments only)


def test_a_subset_of_one_strategy_is_the_single_strategy_weight():
    rng = np.random.default_rng(4)
    paths = random_paths(rng, 200)
    owner, connections, light, eye, light_flags = strategy_batch(paths)
    for target in [(1, 1), (2, 2), (0, 3), (3, 1)]:
        single = mis_weights(connections, light, eye, light_flags, False, "single", 1.0, target)
        for heuristic in ("balance", "power", "uniform"):
            only = mis_weights(connections, light, eye, light_flags, False, heuristic, 2.0, subset=StrategySubset([target]))
            np.testing.assert_array_equal(only, single)
        assert single.sum() > 0


def test_subset_specifications():
    table = StrategySubset("s != 0 and t != 0").table(4)
    assert table[0].sum() == 0 and table[:, 0].sum() == 0 and table[1:, 1:].all()
    assert StrategySubset("not (s == 0 or t == 0)") == StrategySubset("s != 0 and t != 0")
    assert StrategySubset([[1, 1]]).table(3).sum() == 1
    for bad in ("s ** 2 > 1", "import os", "x == 1", "s != ", [(0, 1)], [(-1, 3)], [], 7):
        with pytest.raises(ValueError, match="mis_strategies"):
            StrategySubset(bad)
