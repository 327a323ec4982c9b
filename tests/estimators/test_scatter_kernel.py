"""The C kernel of a walk leaving its vertices (ext/scatter.c) against the NumPy code it replaces.

``Walk.scatter`` takes the new throughput, the roulette's decision and the next ray's origin from
``_native.scatter_step``.  The reference below is the NumPy code it replaced.  Compared bit for bit on
throughputs and weights over many decades with zeros, infinities and NaNs, survival probabilities of 0, 1 and
in between (and none) and NaN, NaN uniforms, normals and directions on both sides of the surface, grazing,
and error bounds of zero and of large coordinates, for three and four channels; then the kernel's refusals.
"""
from __future__ import annotations

import numpy as np
import pytest

from pathspace import _native
from pathspace.vecmath import offset_origin


def reference(beta, weight, survival, u, p, normal, eps, wi):
    """The NumPy code of ``Walk.scatter`` before the kernel: (beta, alive, origin)."""
    with np.errstate(invalid="ignore", over="ignore"):
        alive = weight.max(axis=0) > 0
        beta = beta * weight
        if survival is not None:
            alive &= u < survival
            np.divide(beta, survival, out=beta, where=survival > 0)
    return beta, alive, offset_origin(p, normal, eps, wi)


def unit(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(3, n))
    return (v / np.linalg.norm(v, axis=0)).astype(np.float32)


def inputs(seed: int, channels: int, with_survival: bool, n: int = 5000):
    rng = np.random.default_rng(seed)
    beta = 10.0 ** rng.uniform(-150, 150, (channels, n)) * (rng.random((channels, n)) < 0.95)
    weight = 10.0 ** rng.uniform(-150, 150, (channels, n)) * (rng.random((channels, n)) < 0.7) * (rng.random(n) < 0.7)
    weight[:, rng.random(n) < 0.02] = np.inf
    weight[:, rng.random(n) < 0.02] = np.nan
    survival = None
    if with_survival:
        survival = rng.random(n)
        survival[rng.random(n) < 0.1] = 0.0
        survival[rng.random(n) < 0.3] = 1.0
    beta[:, :30] = np.inf                                           # overflowed and undefined throughputs
    beta[:, 30:40] = np.nan
    u = rng.random(n)
    if with_survival:
        survival[40:45], u[45:50] = np.nan, np.nan                  # NaN decides nothing: the lane dies
    p = (rng.normal(size=(3, n)) * 10.0 ** rng.integers(-3, 6, n)).astype(np.float32)
    normal, wi = unit(rng, n), unit(rng, n)
    wi[:, :200] = np.cross(normal[:, :200].T, wi[:, :200].T).T    # grazing: perpendicular to the normal
    eps = (np.abs(p).max(axis=0) * 2.0 ** -20).astype(np.float32) * (rng.random(n) < 0.9)
    return beta, weight, survival, u, p, normal, eps, wi


@pytest.mark.parametrize("channels", [3, 4])
@pytest.mark.parametrize("with_survival", [True, False])
def test_scatter_step_equals_the_numpy_reference(channels, with_survival):
    args = inputs(channels + 10 * with_survival, channels, with_survival)
    got = _native.scatter_step(*args)
    expected = reference(*args)
    for name, a, b in zip(("beta", "alive", "origin"), got, expected):
        assert a.dtype == b.dtype and a.shape == b.shape, name
        np.testing.assert_array_equal(a, b, err_msg=name)
    alive = got[1]
    assert 0.2 < alive.mean() < 0.8                                  # both outcomes are exercised
    assert not np.array_equal(got[2], args[4])                        # and the origins move


def arguments(n: int = 4) -> list:
    return [np.ones((3, n)), np.ones((3, n)), None, np.zeros(n), np.zeros((3, n), np.float32),
            np.ones((3, n), np.float32), np.zeros(n, np.float32), np.ones((3, n), np.float32)]


@pytest.mark.parametrize("position, value, error, match", [
    (0, np.ones((3, 4), np.float32), TypeError, "beta must be a 2D float64"),
    (1, np.ones((3, 5)), ValueError, "must agree"),
    (2, np.ones(5), ValueError, "must agree"),
    (2, np.ones(4, np.float32), TypeError, "survival must be a 1D float64"),
    (3, np.ones((1, 4)), TypeError, "u must be a 1D float64"),
    (4, np.zeros((2, 4), np.float32), ValueError, "must agree"),
    (7, np.ones((4, 3), np.float32).T, ValueError, "wi must be C-contiguous"),
])
def test_scatter_step_refuses_bad_arguments(position, value, error, match):
    args = arguments()
    args[position] = value
    with pytest.raises(error, match=match):
        _native.scatter_step(*args)
