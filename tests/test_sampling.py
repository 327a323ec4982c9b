"""Sampling warps against their densities, and proof that the chi-square test fails when it should."""
from __future__ import annotations

import numpy as np
from scipy import stats

from pathspace import warp
from pathspace.bsdfs import Diffuse
from pathspace.validate import chi2_test_directions, sidak_significance
from pathspace.validate.bsdf import BSDFCheck, bsdf_chi2


def test_uniform_sphere_chi2():
    def sample(u):
        return warp.square_to_uniform_sphere(u), np.ones(u.shape[1], bool)

    result = chi2_test_directions(sample, warp.square_to_uniform_sphere_pdf, sample_count=500_000, seed=3)
    assert result.passed, str(result)


def test_chi2_detects_a_wrong_pdf():
    """Cosine samples checked against the uniform hemisphere density must fail, and fail clearly."""
    check = BSDFCheck(Diffuse((0.5, 0.5, 0.5)), wo=(0, 0, 1))

    def sample(u):
        s = check.sample(np.vstack([u[:1], u]))
        return s.wi, s.pdf > 0

    def uniform_hemisphere(w):
        return np.where(w[2] > 0, 0.5 / np.pi, 0.0)

    result = chi2_test_directions(sample, uniform_hemisphere, sample_count=200_000, seed=1)
    assert not result.passed and result.p_value < 1e-12
    # ... while the same samples pass against the true density.
    assert bsdf_chi2(check, sample_count=200_000, seed=1).passed


def test_chi2_detects_samples_outside_the_support():
    check = BSDFCheck(Diffuse((0.5, 0.5, 0.5)), wo=(0, 0, 1))

    def sample(u):
        s = check.sample(np.vstack([u[:1], u]))
        return s.wi, s.pdf > 0

    def half_support(w):  # the true pdf restricted to x > 0 and renormalised: half the samples are strays
        return np.where((w[2] > 0) & (w[0] > 0), 2 * np.maximum(w[2], 0) / np.pi, 0.0)

    result = chi2_test_directions(sample, half_support, sample_count=100_000, seed=1)
    assert not result.passed and "where the pdf is zero" in result.message


def test_uniform_triangle_is_uniform():
    """Barycentric samples: each of 16 congruent sub-triangles gets 1/16 of the samples (chi-square)."""
    rng = np.random.default_rng(5)
    b1, b2 = warp.square_to_uniform_triangle(rng.random((2, 400_000)))
    assert np.all((b1 >= 0) & (b2 >= 0) & (b1 + b2 <= 1))
    # The regular 4-subdivision of the (b1, b2) right triangle: grid cells split along their anti-diagonal.
    i, j = np.floor(b1 * 4).astype(int), np.floor(b2 * 4).astype(int)
    upper = (b1 * 4 - i) + (b2 * 4 - j) > 1
    cell = (i * 4 + j) * 2 + upper
    counts = np.bincount(cell, minlength=32)
    valid = [(a * 4 + b) * 2 + up for a in range(4) for b in range(4) for up in (0, 1) if a + b + up < 4]
    assert len(valid) == 16 and counts.sum() == counts[valid].sum()
    statistic = ((counts[valid] - 25_000) ** 2 / 25_000).sum()
    assert stats.chi2.sf(statistic, 15) > sidak_significance(0.01, 2)
