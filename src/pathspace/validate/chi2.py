"""Chi-square goodness-of-fit tests of direction samplers against their densities.

Modelled on Mitsuba 3's ``chi2.ChiSquareTest``: draw many samples, histogram
them over the sphere, integrate the claimed pdf over every bin to get the
expected counts, pool bins with small expected counts (below 5, where the
chi-square approximation fails), and compute Pearson's statistic.  The test
fails if the p-value is below the significance level, Sidak-corrected for the
number of tests run, or if samples land where the pdf is zero.

Bins are equal-area cells in (z = cos theta, phi), dz dphi being the solid
angle measure; the pdf is integrated over each cell with adaptive
Gauss-Legendre quadrature (cells split where the integral is not converged).  The resolution adapts to the sample count (about 200 expected
samples per cell) unless given.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import stats

__all__ = ["ChiSquareResult", "chi2_test_directions", "sidak_significance"]

MIN_EXPECTED = 5.0
STRAY_FRACTION = 1e-5


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


def _gauss_cells(pdf, z0, z1, p0, p1, nodes, weights) -> np.ndarray:
    """Gauss-Legendre integral of the pdf over the cells [z0, z1] x [p0, p1] (dz dphi is solid angle)."""
    t = 0.5 * (nodes + 1.0)
    z = z0[:, None] + (z1 - z0)[:, None] * t[None, :]          # (cells, order)
    phi = p0[:, None] + (p1 - p0)[:, None] * t[None, :]
    zz = np.repeat(z[:, :, None], t.size, axis=2)              # (cells, order_z, order_phi)
    pp = np.repeat(phi[:, None, :], t.size, axis=1)
    r = np.sqrt(np.maximum(0.0, 1.0 - zz * zz))
    directions = np.stack((r * np.cos(pp), r * np.sin(pp), zz)).reshape(3, -1)
    values = np.asarray(pdf(directions), dtype=np.float64).reshape(z0.size, t.size, t.size)
    w = 0.5 * weights
    return np.einsum("cij,i,j->c", values, w, w) * (z1 - z0) * (p1 - p0)


def _integrate_pdf(pdf: Callable[[np.ndarray], np.ndarray], res_z: int, res_phi: int, order: int,
                   max_depth: int = 6, tolerance: float = 1e-4) -> np.ndarray:
    """Integral of the pdf over every bin, by adaptive Gauss-Legendre quadrature.

    A cell is split into four while its integral and the sum over its four
    quarters disagree by more than ``tolerance`` (relative to the whole
    sphere's integral), so narrow lobes are integrated as well as smooth ones.
    """
    nodes, weights = np.polynomial.legendre.leggauss(order)
    iz, iphi = np.meshgrid(np.arange(res_z), np.arange(res_phi), indexing="ij")
    owner = (iz * res_phi + iphi).ravel()
    z0 = -1.0 + 2.0 * iz.ravel() / res_z
    z1 = z0 + 2.0 / res_z
    p0 = -np.pi + 2 * np.pi * iphi.ravel() / res_phi
    p1 = p0 + 2 * np.pi / res_phi
    coarse = _gauss_cells(pdf, z0, z1, p0, p1, nodes, weights)
    total = np.zeros(res_z * res_phi)
    for depth in range(max_depth + 1):
        zm, pm = 0.5 * (z0 + z1), 0.5 * (p0 + p1)
        quarters = [(z0, zm, p0, pm), (z0, zm, pm, p1), (zm, z1, p0, pm), (zm, z1, pm, p1)]
        parts = [_gauss_cells(pdf, *q, nodes, weights) for q in quarters]
        fine = parts[0] + parts[1] + parts[2] + parts[3]
        scale = max(abs(float(fine.sum() + total.sum())), 1e-300)
        done = (np.abs(fine - coarse) <= tolerance * scale / max(fine.size, 1)) | (depth == max_depth)
        np.add.at(total, owner[done], fine[done])
        keep = ~done
        if not keep.any():
            break
        owner = np.tile(owner[keep], 4)
        z0, z1, p0, p1 = (np.concatenate([q[i][keep] for q in quarters]) for i in range(4))
        coarse = np.concatenate([part[keep] for part in parts])
    return total.reshape(res_z, res_phi)


def chi2_test_directions(sample: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                         pdf: Callable[[np.ndarray], np.ndarray], *, sample_count: int = 1_000_000,
                         res_z: int | None = None, res_phi: int | None = None, seed: int = 0,
                         alpha: float = 0.01, test_count: int = 1, quadrature: int = 6,
                         dims: int = 2) -> ChiSquareResult:
    """Test that ``sample`` draws directions with density ``pdf`` (solid angle measure).

    ``sample(u)`` takes (dims, N) uniforms and returns (directions (3, N),
    valid (N,) bool); invalid samples (absorbed, failed) count toward N but
    land in no bin, so the pdf may integrate to less than one.
    ``pdf(directions)`` returns (N,) densities.
    """
    rng = np.random.default_rng(seed)
    if res_z is None or res_phi is None:
        cells = max(16, int(sample_count / 200))
        res_z = res_z or max(4, int(np.sqrt(cells / 2)))
        res_phi = res_phi or 2 * res_z
    directions, valid = sample(rng.random((dims, sample_count)))
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
    # Samples where the integrated pdf is zero mean sampling outside the support -- or, for a pdf with
    # a discontinuity, a sliver of support that no quadrature node of its bin saw.  A handful (at most
    # STRAY_FRACTION of all samples) is put down to the latter and pooled; more fail the test.
    stray = observed[expected == 0].sum()
    if stray > max(STRAY_FRACTION * sample_count, 0):
        return result(False, np.inf, 0, 0.0, f"{int(stray)} samples fell where the pdf is zero")
    support = expected > 0
    order = np.argsort(expected[support])
    exp_sorted, obs_sorted = expected[support][order], observed[support][order]
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
