"""The chi-square harness (pathspace.validate.chi2) fails when it should -- a wrong density, samples where
the density is zero or not finite, samples missing that the density expects -- and only then: samples on a
support's edge rounded to float32 are not strays, invalid samples are expected where the density leaves mass
out."""
from __future__ import annotations

import numpy as np
import pytest

from pathspace.bsdfs import Diffuse
from pathspace.validate import PlaneDomain, SphereDomain, Support, chi2_test, chi2_test_directions, sidak_significance
from pathspace.validate.bsdf import BSDFCheck, bsdf_chi2


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



def cone_sampler(axis, angle: float, *, beyond: float = 0.0, on_edge: float = 0.0):
    """Uniform directions in a cone (as float32), optionally moving a fraction ``on_edge`` of them onto the
    cone's edge and pushing them ``beyond`` radians past it."""
    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    s, t = np.linalg.svd(axis[None, :])[2][1:]

    def sample(u):
        cos = 1 - u[0] * (1 - np.cos(angle))
        edge = u[0] < on_edge
        theta = np.where(edge, angle + beyond, np.arccos(cos))
        phi = 2 * np.pi * u[1]
        w = (np.outer(s, np.sin(theta) * np.cos(phi)) + np.outer(t, np.sin(theta) * np.sin(phi))
             + np.outer(axis, np.cos(theta)))
        return w.astype(np.float32)

    def pdf(w):
        return np.where(axis @ w >= np.cos(angle), 1 / (2 * np.pi * (1 - np.cos(angle))), 0.0)

    return sample, pdf


def test_samples_on_an_edge_are_not_strays():
    """Samples exactly on a cone's edge, rounded to float32 (half of them just outside), are inside the
    support for the harness; the same samples 1e-3 rad outside are not."""
    axis, angle = (0.3, -1.0, 0.2), np.radians(5.0)
    sample, pdf = cone_sampler(axis, angle, on_edge=0.02)
    domain = SphereDomain(axis, 1.2 * angle)
    result = chi2_test(domain, sample, pdf, support=Support.cone(axis, angle), sample_count=100_000)
    assert result.outside == 0, str(result)   # the edge holds no mass, so the p-value may fail: not the point
    outside, _ = cone_sampler(axis, angle, on_edge=0.02, beyond=1e-3)
    result = chi2_test(domain, outside, pdf, support=Support.cone(axis, angle), sample_count=100_000)
    assert not result.passed and result.outside > 1000, str(result)


def test_non_finite_samples_fail():
    def sample(u):
        w = np.asarray(cone_sampler((0, 0, 1), 0.5)[0](u), dtype=np.float64)
        w[:, :3] = np.nan
        return w

    result = chi2_test(SphereDomain(), sample, cone_sampler((0, 0, 1), 0.5)[1], sample_count=50_000)
    assert not result.passed and result.nonfinite == 3 and "not finite" in result.message, str(result)


def test_invalid_samples_are_expected_where_the_density_leaves_mass_out():
    """A sampler that fails 10% of the time and a density integrating to 0.9 agree; a density integrating to
    0.9 with a sampler that never fails does not (the 'rest' category catches the missing 10%)."""
    sample, pdf = cone_sampler((0, 0, 1), 0.5)

    def failing(u):
        return sample(u[:2]), u[2] >= 0.1

    def pdf_90(w):
        return 0.9 * pdf(w)

    support = Support.cone((0, 0, 1), 0.5)
    result = chi2_test(SphereDomain(), failing, pdf_90, support=support, sample_count=200_000, seed=4, dims=3)
    assert result.passed and result.invalid > 19_000 and abs(result.pdf_integral - 0.9) < 1e-12, str(result)
    result = chi2_test(SphereDomain(), sample, pdf_90, support=support, sample_count=200_000, seed=4)
    assert not result.passed and result.p_value < 1e-12, str(result)


def test_report_and_family_significance():
    sample, pdf = cone_sampler((0, 0, 1), 0.5)
    result = chi2_test(SphereDomain((0, 0, 1), 0.6), sample, pdf, support=Support.cone((0, 0, 1), 0.5),
                       sample_count=50_000, test_count=12)
    assert result.significance == sidak_significance(0.01, 12)
    assert 1 - (1 - result.significance) ** 12 == pytest.approx(0.01)
    text = str(result)
    assert text.startswith("PASSED") and "pdf integral=1.000000" in text and "Support(cap" in text
    assert result.expected.shape == result.observed.shape == SphereDomain().default_res(250)


def test_plane_domain_with_an_exact_integral():
    """The plane harness with a caller's exact cell integrals: x uniform, y with density 2 y."""
    def sample(u):
        return np.stack((u[0], np.sqrt(u[1])))

    result = chi2_test(PlaneDomain.unit_square(), sample, lambda p: 2 * p[1],
                       integral=lambda x0, x1, y0, y1: (x1 - x0) * (y1 ** 2 - y0 ** 2), sample_count=100_000,
                       seed=3)
    assert result.passed and result.integral_error == 0 and abs(result.pdf_integral - 1) < 1e-14, str(result)
    with pytest.raises(ValueError, match="shape"):
        chi2_test(PlaneDomain.unit_square(), lambda u: u[:1], lambda p: np.ones(p.shape[1]), sample_count=100)


@pytest.mark.parametrize("case", ["plane-exact", "cone-support"])
def test_p_values_are_uniform_for_a_correct_sampler(case):
    """The harness does not cry wolf: over 40 seeds, the p-values of exact samplers are uniform
    (Kolmogorov-Smirnov), with exact cell integrals and with the quadrature over a support's edges."""
    from scipy import stats

    if case == "plane-exact":
        def run(seed):
            return chi2_test(PlaneDomain.unit_square(), lambda u: np.stack((u[0], np.sqrt(u[1]))), lambda p: 2 * p[1],
                             integral=lambda x0, x1, y0, y1: (x1 - x0) * (y1 ** 2 - y0 ** 2), sample_count=20_000,
                             seed=seed)
    else:
        axis, angle = (0.3, -1.0, 0.2), 0.2
        sample, pdf = cone_sampler(axis, angle)
        domain, support = SphereDomain(axis, 1.3 * angle), Support.cone(axis, angle)

        def run(seed):
            return chi2_test(domain, sample, pdf, support=support, sample_count=20_000, seed=seed)

    p_values = [run(seed).p_value for seed in range(40)]
    assert stats.kstest(p_values, "uniform").pvalue > 1e-3, np.sort(p_values)
