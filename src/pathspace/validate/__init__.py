"""Statistical validation: chi-square tests of samplers and scenes with analytic answers."""
from .chi2 import ChiSquareResult, chi2_test_directions, sidak_significance
from .furnace import furnace_radiance, furnace_scene

__all__ = ["ChiSquareResult", "chi2_test_directions", "furnace_radiance", "furnace_scene", "sidak_significance"]
