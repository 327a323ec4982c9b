"""The C kernels of explicit paths (ext/paths.c) against the NumPy code they replace.

``paths.evaluate`` takes every segment's unit direction and its |cos| / d^2 at both ends from
``_native.path_geometry``; here the former NumPy code is the reference, on random paths of every length
(none, full), at scales from 1e-3 to 1e4, with zero-length segments (NaN direction, zero factors) and
grazing segments; ``path_mutations.split_densities`` sums the densities of regenerating a run of vertices
over its splits with ``_native.split_densities``, checked bit for bit against the former NumPy code.
"""
from __future__ import annotations

import numpy as np
import pytest

from pathspace import _native


def reference_geometry(p: np.ndarray, n: np.ndarray, k: np.ndarray):
    """The NumPy expressions paths.evaluate computed before the kernel: (w, g_fwd, g_rev, segments)."""
    count, slots = p.shape[1:]
    p, n = p.astype(np.float64), n.astype(np.float64)
    edge = p[:, :, 1:] - p[:, :, :-1]
    dist2 = (edge * edge).sum(axis=0)
    on_path = np.arange(slots - 1)[None, :] < k[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where(on_path, edge / np.sqrt(np.where(on_path, dist2, 1.0)), 0.0)
        cos_start = np.abs((n[:, :, :-1] * w).sum(axis=0))
        cos_end = np.abs((n[:, :, 1:] * w).sum(axis=0))
        g_fwd, g_rev = np.zeros((count, slots)), np.zeros((count, slots))
        g_fwd[:, 1:] = np.where(on_path & (dist2 > 0), cos_end / dist2, 0.0)
        g_rev[:, :-1] = np.where(on_path & (dist2 > 0), cos_start / dist2, 0.0)
    segments = np.where(on_path, np.divide(cos_start, dist2, out=np.zeros_like(dist2), where=dist2 > 0), 1.0)
    return w, g_fwd, g_rev, segments.prod(axis=1)


def random_paths(seed: int, count: int, slots: int, scale: float):
    rng = np.random.default_rng(seed)
    p = (rng.normal(size=(3, count, slots)) * scale).astype(np.float32)
    repeat = rng.random((count, slots - 1)) < 0.05                   # zero-length segments
    p[:, :, 1:][:, repeat] = p[:, :, :-1][:, repeat]
    n = rng.normal(size=(3, count, slots))
    n /= np.linalg.norm(n, axis=0)
    grazing = rng.random((count, slots - 1)) < 0.05                  # normals across the segment
    edge = (p[:, :, 1:] - p[:, :, :-1]).astype(np.float64)
    across = np.cross(edge, rng.normal(size=edge.shape), axis=0)
    across /= np.maximum(np.linalg.norm(across, axis=0), 1e-300)
    n[:, :, :-1][:, grazing] = across[:, grazing]
    k = rng.integers(0, slots, count)
    k[:3] = [0, slots - 1, 1]
    return p, n.astype(np.float32), k


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e4])
@pytest.mark.parametrize("slots", [1, 2, 17])
def test_path_geometry_equals_the_numpy_reference(scale, slots):
    p, n, k = random_paths(int(scale * 1000) + slots, 4000, slots, scale)
    if slots == 1:
        k[:] = 0
    got = _native.path_geometry(p, n, k)
    expected = reference_geometry(p, n, k)
    for name, a, b in zip(("w", "g_fwd", "g_rev", "segments"), got, expected):
        assert a.dtype == np.float64 and a.shape == b.shape, name
        np.testing.assert_array_equal(a, b, err_msg=name)    # the same operations in the same order
    if slots > 1:
        degenerate = np.isnan(got[0][0])
        assert degenerate.any() and (got[2][:, :-1][degenerate] == 0).all()


def test_path_geometry_refuses_bad_arguments():
    p, n, k = random_paths(1, 10, 4, 1.0)
    with pytest.raises(ValueError, match=r"k\[0\] = 4: a path of K = 4 vertex slots has 0 .. 3 segments"):
        _native.path_geometry(p, n, np.full(10, 4))
    with pytest.raises(ValueError, match="k must have length N = 10"):
        _native.path_geometry(p, n, k[:5])
    with pytest.raises(ValueError, match="same shape"):
        _native.path_geometry(p, n[:, :5].copy(), k)
    with pytest.raises(TypeError, match="p must be a 3D float32"):
        _native.path_geometry(p.astype(np.float64), n, k)
    with pytest.raises(TypeError, match="k must be a 1D int64"):
        _native.path_geometry(p, n, k.astype(np.int32))


def reference_split_densities(fwd, rev, delta, first, count):
    """The NumPy code path_mutations.split_densities ran before the kernel."""
    size, slots = fwd.shape
    lanes = np.arange(size)
    slot = np.arange(slots)[None, :]
    inside = (slot >= first[:, None]) & (slot < (first + count)[:, None])
    light_walk = np.cumprod(np.where(inside, fwd, 1.0), axis=1)
    camera_walk = np.cumprod(np.where(inside, rev, 1.0)[:, ::-1], axis=1)[:, ::-1]
    total = np.zeros(size)
    for j in range(int(count.max(initial=0)) + 1):
        last = first - 1 + j
        light = np.where(last >= first, light_walk[lanes, np.clip(last, 0, slots - 1)], 1.0)
        camera = np.where(last + 1 < first + count, camera_walk[lanes, np.clip(last + 1, 0, slots - 1)], 1.0)
        joinable = (last < 0) | ~(delta[lanes, np.clip(last, 0, slots - 1)] | delta[lanes, np.clip(last + 1, 0,
                                                                                                   slots - 1)])
        total += np.where((j <= count) & joinable, light * camera, 0.0)
    return total


@pytest.mark.parametrize("slots", [1, 3, 17])
def test_split_densities_equal_the_numpy_reference(slots):
    """Bit for bit, on densities over 600 decades, specular vertices, and runs that reach past the last slot
    (the bidirectional mutation asks for those too, on paths it then drops)."""
    rng = np.random.default_rng(slots)
    n = 5000
    fwd = 10.0 ** rng.uniform(-300, 300, (n, slots)) * (rng.random((n, slots)) > 0.05)
    rev = 10.0 ** rng.uniform(-300, 300, (n, slots)) * (rng.random((n, slots)) > 0.05)
    delta = rng.random((n, slots)) < 0.15
    first = rng.integers(0, slots + 2, n)
    count = rng.integers(0, slots + 2, n)
    first[:4], count[:4] = [0, 0, slots - 1, 0], [0, slots - 1, 1, slots]
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        expected = reference_split_densities(fwd, rev, delta, first, count)
    got = _native.split_densities(fwd, rev, delta, first, count)
    np.testing.assert_array_equal(got, expected)
    assert np.isinf(got).any() and (got == 0).any() and ((got > 0) & np.isfinite(got)).mean() > 0.3


def test_split_densities_refuse_bad_arguments():
    fwd = np.ones((4, 3))
    delta = np.zeros((4, 3), bool)
    with pytest.raises(ValueError, match=r"first\[2\] = -1 and count\[2\] = 1: both must be >= 0"):
        _native.split_densities(fwd, fwd, delta, np.array([0, 0, -1, 0]), np.ones(4, np.int64))
    with pytest.raises(ValueError, match="one shape"):
        _native.split_densities(fwd, fwd[:, :2].copy(), delta, np.zeros(4, np.int64), np.ones(4, np.int64))
    with pytest.raises(TypeError, match="delta must be a 2D bool"):
        _native.split_densities(fwd, fwd, fwd, np.zeros(4, np.int64), np.ones(4, np.int64))
