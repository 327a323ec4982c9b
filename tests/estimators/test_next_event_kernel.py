"""The C kernel of path tracing's light samples (ext/direct.c) against the NumPy code it replaces.

``PathTracer._next_event`` takes the MIS-weighted value of its light samples, and which of them deserve a
shadow ray, from ``_native.next_event_value``.  The reference below is the NumPy code it replaced, with one
change: a light sample is useful if *any* channel of f |cos| is positive (the NumPy code read only the first
three, which dropped spectral paths whose reflectance was zero at three of their four wavelengths).
Compared bit for bit on densities over six hundred decades, zeros, infinities and NaNs, with and without
delta lights, for every heuristic and three or four channels; a power heuristic's exponent other than 2 goes
through C's ``pow``, compared to within a few ulps.  Then the kernel's refusals.
"""
from __future__ import annotations

import numpy as np
import pytest

from pathspace import _native
from pathspace.estimators.pt import MIS_CODES
from pathspace.mis import mis_weight


def reference(beta, f_cos, le, pdf_light, pdf_bsdf, facing, delta, heuristic, exponent):
    """The NumPy code of ``PathTracer._next_event`` before the kernel (value, useful)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = 1.0 / pdf_light
        if heuristic != "none":
            w = mis_weight(pdf_light, pdf_bsdf, heuristic, exponent)
            scale *= np.where(delta, 1.0, w) if delta is not None else w
        useful = facing & (scale > 0) & (f_cos.max(axis=0) > 0)
        return np.where(useful, beta * f_cos * (le * scale), 0.0), useful


def densities(rng: np.random.Generator, n: int) -> np.ndarray:
    """Densities from 1e-300 to 1e300, with zeros, infinities and NaNs among them."""
    pdf = 10.0 ** rng.uniform(-300, 300, n)
    special = rng.random(n)
    pdf[special < 0.05] = 0.0
    pdf[(special >= 0.05) & (special < 0.08)] = np.inf
    pdf[(special >= 0.08) & (special < 0.09)] = np.nan
    return pdf


def inputs(seed: int, channels: int, n: int = 4000, with_delta: bool = True):
    rng = np.random.default_rng(seed)
    beta = rng.exponential(1.0, (channels, n)) * (rng.random((channels, n)) < 0.9)
    f_cos = rng.exponential(1.0, (channels, n)) * (rng.random((channels, n)) < 0.6)
    f_cos[:, rng.random(n) < 0.02] = np.nan
    le = rng.exponential(10.0, (channels, n))
    pdf_light, pdf_bsdf = densities(rng, n), densities(rng, n)
    pdf_bsdf[:50] = pdf_light[:50]           # equal densities: weight 1/2 (inf/inf, 0/0 included)
    facing = rng.random(n) < 0.8
    delta = rng.random(n) < 0.2 if with_delta else None
    return beta, f_cos, le, pdf_light, pdf_bsdf, facing, delta


@pytest.mark.parametrize("channels", [3, 4])
@pytest.mark.parametrize("with_delta", [True, False])
@pytest.mark.parametrize("heuristic, exponent", [("none", 2.0), ("balance", 2.0), ("power", 2.0),
                                                 ("uniform", 2.0)])
def test_next_event_value_equals_the_numpy_reference(channels, with_delta, heuristic, exponent):
    args = inputs(channels * 10 + with_delta, channels, with_delta=with_delta)
    value, useful = _native.next_event_value(*args, MIS_CODES[heuristic], exponent)
    expected_value, expected_useful = reference(*args, heuristic, exponent)
    np.testing.assert_array_equal(useful, expected_useful)
    np.testing.assert_array_equal(value, expected_value)
    assert value.dtype == np.float64 and value.shape == args[0].shape and useful.dtype == bool
    assert 0.2 < useful.mean() < 0.8        # the inputs exercise both outcomes


@pytest.mark.parametrize("exponent", [0.5, 3.0, 7.5])
def test_a_power_heuristic_of_another_exponent_is_within_ulps(exponent):
    args = inputs(7, 3)
    value, useful = _native.next_event_value(*args, MIS_CODES["power"], exponent)
    expected_value, expected_useful = reference(*args, "power", exponent)
    np.testing.assert_array_equal(useful, expected_useful)
    np.testing.assert_allclose(value, expected_value, rtol=1e-14, atol=0.0)


def test_a_light_sample_is_useful_when_only_its_fourth_wavelength_reflects():
    beta, f_cos, le = np.ones((4, 2)), np.zeros((4, 2)), np.ones((4, 2))
    f_cos[3] = 0.5
    value, useful = _native.next_event_value(beta, f_cos, le, np.array([2.0, 2.0]), np.array([2.0, 0.0]),
                                             np.array([True, False]), None, MIS_CODES["balance"], 2.0)
    np.testing.assert_array_equal(useful, [True, False])
    np.testing.assert_array_equal(value[:, 0], [0.0, 0.0, 0.0, 0.5 * 0.5 * 0.5])   # beta f (le w / pdf)
    np.testing.assert_array_equal(value[:, 1], 0.0)


def arguments(n: int = 4) -> list:
    return [np.ones((3, n)), np.ones((3, n)), np.ones((3, n)), np.ones(n), np.ones(n), np.ones(n, bool), None,
            MIS_CODES["power"], 2.0]


@pytest.mark.parametrize("position, value, error, match", [
    (0, np.ones((3, 4), np.float32), TypeError, "beta must be a 2D float64"),
    (1, np.ones((4, 3)).T, ValueError, "f_cos must be C-contiguous"),
    (2, np.ones((2, 4)), ValueError, "must agree"),
    (3, np.ones(5), ValueError, "must agree"),
    (5, np.ones(4), TypeError, "facing must be a 1D bool"),
    (6, np.ones(3, bool), ValueError, "must agree"),
    (7, 4, ValueError, "heuristic must be"),
])
def test_next_event_value_refuses_bad_arguments(position, value, error, match):
    args = arguments()
    args[position] = value
    with pytest.raises(error, match=match):
        _native.next_event_value(*args)
