"""Sampling warps (pathspace.warp) against their densities: uniform sphere (chi-square over directions),
uniform triangle (chi-square over 16 congruent sub-triangles)."""
from __future__ import annotations

import numpy as np
from scipy import stats

from pathspace import warp
from pathspace.validate import chi2_test_directions, sidak_significance


def test_uniform_sphere_chi2():
    def sample(u):
        return warp.square_to_uniform_sphere(u), np.ones(u.shape[1], bool)

    result = chi2_test_directions(sample, warp.square_to_uniform_sphere_pdf, sample_count=500_000, seed=3)
    assert result.passed, str(result)


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

