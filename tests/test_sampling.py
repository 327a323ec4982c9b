"""Sampling routines against their densities: chi-square tests, and a test that the test can fail."""
from __future__ import annotations

import numpy as np
import pytest

from pathspace import materials, warp
from pathspace.validate import chi2_test_directions, sidak_significance

NORMALS = {
    "+z": [0.0, 0.0, 1.0],
    "-x": [-1.0, 0.0, 0.0],
    "oblique": [0.3, -0.5, 0.81],
}
TESTS = len(NORMALS) + 1  # Sidak correction over the tests of this module that should pass


def diffuse_sampler(normal):
    n = np.asarray(normal, dtype=np.float32)
    n /= np.linalg.norm(n)

    def sample(u):
        nn = np.repeat(n[:, None], u.shape[1], axis=1)
        wi, pdf = materials.diffuse_sample(nn, u)
        # The returned pdf is the density at the returned direction.
        np.testing.assert_allclose(pdf, materials.diffuse_cos_over_pi(n @ wi), rtol=1e-5, atol=1e-7)
        ok = (pdf > 0) & np.all(np.isfinite(wi), axis=0)
        return wi, ok

    def pdf(w):
        return materials.diffuse_cos_over_pi(n[0] * w[0] + n[1] * w[1] + n[2] * w[2])

    return sample, pdf


@pytest.mark.parametrize("normal", NORMALS.values(), ids=NORMALS.keys())
def test_cosine_sampling_chi2(normal):
    sample, pdf = diffuse_sampler(normal)
    result = chi2_test_directions(sample, pdf, sample_count=500_000, seed=7, test_count=TESTS)
    assert result.passed, str(result)
    assert abs(result.pdf_integral - 1.0) < 1e-3


def test_uniform_sphere_chi2():
    def sample(u):
        return warp.square_to_uniform_sphere(u), np.ones(u.shape[1], bool)

    result = chi2_test_directions(sample, warp.square_to_uniform_sphere_pdf, sample_count=500_000, seed=3,
                                  test_count=TESTS)
    assert result.passed, str(result)


def test_chi2_detects_a_wrong_pdf():
    """Cosine samples checked against the uniform hemisphere density must fail, and fail clearly."""
    sample, _ = diffuse_sampler([0, 0, 1])

    def uniform_hemisphere(w):
        return np.where(w[2] > 0, 0.5 / np.pi, 0.0)

    result = chi2_test_directions(sample, uniform_hemisphere, sample_count=200_000, seed=1)
    assert not result.passed
    assert result.p_value < 1e-12


def test_chi2_detects_samples_outside_the_support():
    sample, _ = diffuse_sampler([0, 0, 1])

    def upper_quarter(w):  # the true pdf restricted to x > 0 and renormalised: half the samples are strays
        return np.where((w[2] > 0) & (w[0] > 0), 2 * np.maximum(w[2], 0) / np.pi, 0.0)

    result = chi2_test_directions(sample, upper_quarter, sample_count=100_000, seed=1)
    assert not result.passed and "where the pdf is zero" in result.message


def test_uniform_triangle_is_uniform():
    """Barycentric samples: each of 16 congruent sub-triangles gets 1/16 of the samples (chi-square)."""
    from scipy import stats

    rng = np.random.default_rng(5)
    b1, b2 = warp.square_to_uniform_triangle(rng.random((2, 400_000)))
    assert np.all((b1 >= 0) & (b2 >= 0) & (b1 + b2 <= 1))
    # Subdivide into 4x4 grid cells of the (b1, b2) right triangle: cells below the diagonal are whole
    # squares split in two; index the 16 sub-triangles of the regular 4-subdivision.
    i, j = np.floor(b1 * 4).astype(int), np.floor(b2 * 4).astype(int)
    upper = (b1 * 4 - i) + (b2 * 4 - j) > 1
    cell = (i * 4 + j) * 2 + upper
    counts = np.bincount(cell, minlength=32)
    valid = [(a * 4 + b) * 2 + up for a in range(4) for b in range(4) for up in (0, 1) if a + b + up < 4]
    assert len(valid) == 16 and counts.sum() == counts[valid].sum()
    statistic = ((counts[valid] - 25_000) ** 2 / 25_000).sum()
    assert stats.chi2.sf(statistic, 15) > sidak_significance(0.01, TESTS)
