"""Multiple importance sampling weights for two strategies, from pdf ratios.

Veach 1997, section 9.2: the balance heuristic w_a = p_a / (p_a + p_b) and the
power heuristic w_a = p_a^beta / (p_a^beta + p_b^beta) (eq. 9.13), written as
1 / (1 + (p_b / p_a)^beta) so that no power of a raw pdf is ever formed; and
the uniform weights w = 1 / (number of strategies that can produce the sample).
A strategy with pdf 0 gets weight 0 and leaves weight 1 to the other; two
delta strategies (both pdfs infinite) share equally.
"""
from __future__ import annotations

import numpy as np

__all__ = ["HEURISTICS", "mis_weight"]

HEURISTICS = ("balance", "power", "uniform")


def mis_weight(pdf_a: np.ndarray, pdf_b: np.ndarray, heuristic: str = "power", beta: float = 2.0) -> np.ndarray:
    """Weight of strategy a against strategy b (both pdfs in the same measure), float64."""
    if heuristic not in HEURISTICS:
        raise ValueError(f"MIS heuristic: expected one of {HEURISTICS}, got {heuristic!r}")
    a = np.asarray(pdf_a, dtype=np.float64)
    b = np.asarray(pdf_b, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if heuristic == "uniform":
            ratio = np.where(a > 0, (b > 0).astype(np.float64), np.inf)
        else:
            ratio = b / a  # 0/x -> 0, x/0 -> inf, inf/inf -> nan
            if heuristic == "power":
                ratio = ratio * ratio if beta == 2.0 else ratio ** beta
        weight = np.asarray(1.0 / (1.0 + ratio))  # a = 0 < b: ratio inf, weight 0
    undefined = np.isnan(weight)  # 0/0: neither applies (0); inf/inf: two delta strategies (1/2 each)
    if undefined.any():
        weight = np.where(undefined, np.where(np.isinf(a), 0.5, 0.0), weight)
    return weight
