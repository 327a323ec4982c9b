"""Two-strategy MIS weights: ratio form, zero-pdf strategies, and partition of unity."""
from __future__ import annotations

import numpy as np
import pytest

from pathspace.mis import mis_weight


@pytest.mark.parametrize("heuristic, beta", [("balance", 1.0), ("power", 2.0), ("power", 3.5)])
def test_weights_sum_to_one_over_many_decades(heuristic, beta):
    rng = np.random.default_rng(0)
    a = 10.0 ** rng.uniform(-300, 300, 100_000)
    b = 10.0 ** rng.uniform(-300, 300, 100_000)
    wa, wb = mis_weight(a, b, heuristic, beta), mis_weight(b, a, heuristic, beta)
    np.testing.assert_allclose(wa + wb, 1.0, rtol=1e-12)
    assert np.all((wa >= 0) & (wa <= 1))
    # Against the textbook formula where it does not overflow.
    ok = (np.abs(np.log10(a)) < 50) & (np.abs(np.log10(b)) < 50)
    textbook = a[ok] ** beta / (a[ok] ** beta + b[ok] ** beta) if heuristic == "power" else a[ok] / (a[ok] + b[ok])
    np.testing.assert_allclose(wa[ok], textbook, rtol=1e-10, atol=1e-300)


def test_strategies_that_cannot_sample_get_zero_weight():
    w = mis_weight(np.array([0.0, 1.0, 0.0, np.inf]), np.array([1.0, 0.0, 0.0, 1.0]))
    np.testing.assert_array_equal(w, [0.0, 1.0, 0.0, 1.0])
    assert mis_weight(np.float64(2.0), np.float64(1.0)) == pytest.approx(0.8)
    with pytest.raises(ValueError, match="MIS heuristic"):
        mis_weight(np.ones(1), np.ones(1), "maximum")
