"""The render summary names what a Metropolis render's b is the mean of."""
from __future__ import annotations

import numpy as np
import pytest

from pathspace.driver import RenderResult


def metropolis_result(params: dict) -> RenderResult:
    stats = {"estimator": "pssmlt", "mode": "rgb", "spp": 4, "width": 8, "height": 8, "seconds": 1.0,
             "samples_per_second": 1e6, "rays_per_second": 2e6, "threads": 2, "params": params,
             "metropolis": {"chains": 256, "mutations": 10 ** 6, "mutations_per_second": 5e5, "brightness": 0.148, "bootstrap": 4096,
                            "brightness_standard_error": 0.002, "longest_rejection_run": 12},
             "nonfinite": 0, "nonfinite_contributions": 0, "truncated": 0, "resumed": None, "stopped": None,
             "warnings": []}
    return RenderResult(np.zeros((8, 8, 3)), np.full((8, 8, 3), np.nan), stats, None)


@pytest.mark.parametrize("kind,label", [("luminance", "mean contribution b (luminance) 0.148 +- 0.002"),
                                        ("xyz", "mean contribution b (X+Y+Z) 0.148 +- 0.002"),
                                        ("max", "mean contribution b (max channel) 0.148 +- 0.002"),
                                        (None, "mean contribution b 0.148 +- 0.002")])
def test_the_summary_says_what_b_is(kind, label):
    params = {"chains": 256} if kind is None else {"chains": 256, "contribution": kind}
    summary = metropolis_result(params).summary()
    assert label in summary and "brightness" not in summary
