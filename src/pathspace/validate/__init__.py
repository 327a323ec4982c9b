"""Statistical validation: chi-square tests of samplers, estimator comparison, analytic scenes."""
from .chi2 import ChiSquareResult, chi2_test, chi2_test_directions, integrate_bins, sidak_significance
from .compare import ComparisonResult, compare_estimates
from .domains import PlaneDomain, SphereDomain, Support
from .furnace import furnace_radiance, furnace_scene

__all__ = [
    "ChiSquareResult",
    "ComparisonResult",
    "PlaneDomain",
    "SphereDomain",
    "Support",
    "chi2_test",
    "chi2_test_directions",
    "compare_estimates",
    "furnace_radiance",
    "furnace_scene",
    "integrate_bins",
    "sidak_significance",
]
