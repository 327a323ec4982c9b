"""Chi-square goodness-of-fit tests of direction samplers against their densities.

Modelled on Mitsuba 3's ``chi2.ChiSquareTest``: draw many samples, histogram
them over the sphere, integrate the claimed pdf over every bin to get the
expected counts, pool bins with small expected counts (below 5, where the
chi-square approximation fails), and compute Pearson's statistic.  The test
fails if the p-value is below the significance level, Sidak-corrected for the
number of tests run, or if samples land where the pdf is zero.

Bins are equal-area cells in (z = cos theta, phi), dz dphi being the solid
angle measure; the pdf is integrated over each cell with Gauss-Legendre
quadrature.  The resolution adapts to the sample count (about 200 expected
samples per cell) unless given.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import stats

__all__ = ["ChiSquareResult", "chi2_test_directions", "sidak_significance"]

MIN_EXPECTED = 5.0


def sidak_significance(alpha: float, test_count: int) -> float:
    """Per-test significance so that ``test_count`` independent tests have family-wise error ``alpha``."""
    return 1.0 - (1.0 - alpha) ** (1.0 / max(int(test_count), 1))


@dataclass
class ChiSquareResult:
    """Outcome of a chi-square test; ``str()`` gives a readable report."""

    passed: bool
    statistic: float
    dof: int
    p_value: float
    significance: float
    pdf_integral: float
    message: str
    observed: np.ndarray
    expected: np.ndarray

    def __str__(self) -> str:
        return (f"{'PASSED' if self.passed else 'FAILED'}: {self.message} (chi2={self.statistic:.1f}, dof={self.dof}, "
                f"p={self.p_value:.3g}, significance={self.significance:.3g}, pdf integral={self.pdf_integral:.5f})")


def _bin_index(directions: np.ndarray, res_z: int, res_phi: int) -> np.ndarray:
    z = np.clip(directions[2].astype(np.float64), -1.0, 1.0)
    phi = np.arctan2(directions[1].astype(np.float64), directions[0].astype(np.float64))
    iz = np.clip(((z + 1.0) * 0.5 * res_z).astype(np.int64), 0, res_z - 1)
    iphi = np.clip(((phi + np.pi) / (2 * np.pi) * res_phi).astype(np.int64), 0, res_phi - 1)
    return iz * res_phi + iphi


def _integrate_pdf(pdf: Callable[[np.ndarray], np.ndarray], res_z: int, res_phi: int, order: int) -> np.ndarray:
    nodes, weights = np.polynomial.legendre.leggauss(order)
    dz, dphi = 2.0 / res_z, 2 * np.pi / res_phi
    z0 = -1.0 + dz * np.arange(res_z)
    phi0 = -np.pi + dphi * np.arange(res_phi)
    # Quadrature points of every cell: (res_z, order) x (res_phi, order).
    z = (z0[:, None] + dz * 0.5 * (nodes + 1.0)[None, :]).ravel()
    phi = (phi0[:, None] + dphi * 0.5 * (nodes + 1.0)[None, :]).ravel()
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    r = np.sqrt(np.maximum(0.0, 1.0 - zz * zz))
    directions = np.stack((r * np.cos(pp), r * np.sin(pp), zz)).reshape(3, -1)
    values = np.asarray(pdf(directions), dtype=np.float64).reshape(res_z, order, res_phi, order)
    w = weights * 0.5
    return np.einsum("aibj,i,j->ab", values, w, w) * dz * dphi


def chi2_test_directions(sample: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                         pdf: Callable[[np.ndarray], np.ndarray], *, sample_count: int = 1_000_000,
                         res_z: int | None = None, res_phi: int | None = None, seed: int = 0,
                         alpha: float = 0.01, test_count: int = 1, quadrature: int = 6) -> ChiSquareResult:
    """Test that ``sample`` draws directions with density ``pdf`` (solid angle measure).

    ``sample(u)`` takes (2, N) uniforms and returns (directions (3, N), valid
    (N,) bool); invalid samples (absorbed, failed) count toward N but land in
    no bin, so the pdf may integrate to less than one.  ``pdf(directions)``
    returns (N,) densities.
    """
    rng = np.random.default_rng(seed)
    if res_z is None or res_phi is None:
        cells = max(16, int(sample_count / 200))
        res_z = res_z or max(4, int(np.sqrt(cells / 2)))
        res_phi = res_phi or 2 * res_z
    directions, valid = sample(rng.random((2, sample_count)))
    directions = np.asarray(directions)[:, np.asarray(valid, dtype=bool)]
    observed = np.bincount(_bin_index(directions, res_z, res_phi), minlength=res_z * res_phi).astype(np.float64)
    expected = _integrate_pdf(pdf, res_z, res_phi, quadrature).ravel() * sample_count
    integral = float(expected.sum() / sample_count)
    significance = sidak_significance(alpha, test_count)

    def result(passed, statistic, dof, p, message):
        return ChiSquareResult(passed, statistic, dof, p, significance, integral, message,
                               observed.reshape(res_z, res_phi), expected.reshape(res_z, res_phi))

    if not np.all(np.isfinite(expected)) or np.any(expected < 0):
        return result(False, np.inf, 0, 0.0, "the pdf is negative or not finite somewhere")
    if integral > 1.0 + 1e-3:
        return result(False, np.inf, 0, 0.0, f"the pdf integrates to {integral:.5f} > 1 over the sphere")
    stray = observed[expected == 0].sum()
    if stray > 0:
        return result(False, np.inf, 0, 0.0, f"{int(stray)} samples fell where the pdf is zero")
    order = np.argsort(expected)
    exp_sorted, obs_sorted = expected[order], observed[order]
    small = exp_sorted < MIN_EXPECTED
    pooled_exp, pooled_obs = exp_sorted[small].sum(), obs_sorted[small].sum()
    exp_kept, obs_kept = exp_sorted[~small], obs_sorted[~small]
    if pooled_exp > 0:
        exp_kept = np.append(exp_kept, pooled_exp)
        obs_kept = np.append(obs_kept, pooled_obs)
    # Samples the pdf says should not exist at all (pdf integral < 1 but invalid fraction smaller) show up
    # as a mismatch in the total; fold the remainder into one more cell.
    rest_exp = sample_count - exp_kept.sum()
    rest_obs = sample_count - obs_kept.sum()
    if rest_exp >= MIN_EXPECTED:
        exp_kept = np.append(exp_kept, rest_exp)
        obs_kept = np.append(obs_kept, rest_obs)
    dof = exp_kept.size - 1
    if dof < 1:
        return result(False, np.inf, 0, 0.0, "too few populated bins for a test")
    statistic = float(np.sum((obs_kept - exp_kept) ** 2 / exp_kept))
    p_value = float(stats.chi2.sf(statistic, dof))
    passed = p_value >= significance
    message = ("samples are consistent with the pdf" if passed
               else "samples are not distributed according to the pdf")
    return result(passed, statistic, dof, p_value, message)
