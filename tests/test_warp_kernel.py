"""The C kernel of cosine-weighted directions (ext/warp.c) against the NumPy code it replaces.

``warp.square_to_cosine_about`` (diffuse BSDF sampling, emission from area lights) takes its directions from
``_native.cosine_about``, given the angle's cosine and sine from NumPy.  The reference below is the NumPy code it
replaced.  Compared bit for bit on random normals, axis-aligned ones, and uniforms at the ends of [0, 1) (the
sphere's poles, where the sum n + s can vanish), in float32 and float64 uniforms; then the kernel's refusals.
The warp's density is tested by a chi-square test in tests/validate/test_routines.py.
"""
from __future__ import annotations

import numpy as np
import pytest

from pathspace import _native, warp


def reference(n: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The NumPy code of ``warp.square_to_cosine_about`` before the kernel."""
    d = n + warp.square_to_uniform_sphere(u)
    length = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    return np.where(length > 1e-6, d / np.maximum(length, np.float32(1e-6)), n)


def normals(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(3, n))
    v = (v / np.linalg.norm(v, axis=0)).astype(np.float32)
    v[:, :6] = np.array([[1, -1, 0, 0, 0, 0], [0, 0, 1, -1, 0, 0], [0, 0, 0, 0, 1, -1]], np.float32)
    return v


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_cosine_about_equals_the_numpy_reference(dtype):
    rng = np.random.default_rng(11)
    n = normals(rng, 20000)
    u = rng.random((2, 20000))
    u[0, 6:12] = [0.0, 0.0, 1.0 - 2.0 ** -53, 1.0 - 2.0 ** -53, 0.5, 0.25]   # poles, equator
    u[1, 6:12] = [0.0, 0.5, 0.25, 0.75, 0.0, 1.0 - 2.0 ** -53]
    n[:, 6:10] = np.array([[0, 0, 0, 0], [0, 0, 0, 0], [-1, -1, 1, 1]], np.float32)   # the pole opposite n: d = 0
    u = u.astype(dtype)
    got = warp.square_to_cosine_about(n, u)
    expected = reference(n, u)
    assert got.dtype == np.float32 and got.shape == (3, 20000)
    np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(got[:, 6:8], n[:, 6:8])      # s = -n: the normal itself


def test_cosine_about_refuses_bad_arguments():
    n, u0, c = np.zeros((3, 4), np.float32), np.zeros(4), np.zeros(4, np.float32)
    with pytest.raises(TypeError, match="n must be a 2D float32"):
        _native.cosine_about(n.astype(np.float64), u0, c, c)
    with pytest.raises(ValueError, match="must agree"):
        _native.cosine_about(n, np.zeros(5), c, c)
    with pytest.raises(ValueError, match="must agree"):
        _native.cosine_about(np.zeros((2, 4), np.float32), u0, c, c)
    with pytest.raises(TypeError, match="sin_phi must be a 1D float32"):
        _native.cosine_about(n, u0, c, np.zeros(4))
