"""Statistical validation: chi-square tests of samplers, estimator comparison, analytic scenes."""
from .chi2 import ChiSquareResult, chi2_test_directions, sidak_significance
from .compare import ComparisonResult, compare_estimates
from .furnace import furnace_radiance, furnace_scene

__all__ = [
    "ChiSquareResult",
    "ComparisonResult",
    "chi2_test_directions",
    "compare_estimates",
    "furnace_radiance",
    "furnace_scene",
    "sidak_significance",
]
