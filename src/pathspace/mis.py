"""Multiple importance sampling weights for two strategies, from pdf ratios.

Veach 1997, section 9.2: the balance heuristic w_a = p_a / (p_a + p_b) and the
power heuristic w_a = p_a^beta / (p_a^beta + p_b^beta) (eq. 9.13), written as
1 / (1 + (p_b / p_a)^beta) so that no power of a raw pdf is ever formed.
A strategy with pdf 0 gets weight 0; against a strategy with pdf 0, weight 1.
"""
from __future__ import annotations

import numpy as np

__all__ = ["HEURISTICS", "mis_weight"]

HEURISTICS = ("balance", "power")


def mis_weight(pdf_a: np.ndarray, pdf_b: np.ndarray, heuristic: str = "power", beta: float = 2.0) -> np.ndarray:
    """Weight of strategy a against strategy b (both pdfs in the same measure), float64."""
    if heuristic not in HEURISTICS:
        raise ValueError(f"MIS heuristic: expected one of {HEURISTICS}, got {heuristic!r}")
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        ratio = np.asarray(pdf_b, dtype=np.float64) / pdf_a  # 0/x -> 0, x/0 -> inf, 0/0 -> nan
        if heuristic == "power":
            ratio = ratio * ratio if beta == 2.0 else ratio ** beta
        weight = np.asarray(1.0 / (1.0 + ratio))  # ratio inf -> 0
    weight[weight != weight] = 0.0  # both pdfs zero (or both infinite): the strategy does not apply
    return weight
