"""Russian roulette: unbiased termination of paths (Arvo & Kirk 1990; Veach 1997, sec. 2.4).

At each scattering vertex from depth ``start_depth`` on, a path survives with
probability q and its throughput is divided by q, so the estimator stays
unbiased for any q in (0, 1].  Policies:

``"off"``         q = 1: paths end only by escaping, absorption or ``max_depth``.
``"fixed"``       q = 1 - ``probability`` (a fixed termination probability).
``"albedo"``      q = the scattering vertex's albedo estimate (the largest
                  channel of the sampled BSDF weight f cos / pdf), capped at 1.
``"throughput"``  q = min(largest channel of the path throughput, ``cap``): paths
                  carrying little energy end early, and a surviving path's
                  throughput is lifted back toward 1.  The default, with cap 1
                  as in pbrt-v4.  Mitsuba 3 caps at 0.95, which gives an
                  estimator of infinite variance wherever the albedo exceeds
                  the cap (throughput then grows by albedo / cap per bounce):
                  in an albedo-0.99 furnace its finite-sample means fall ~10%
                  short.

Depth counts path segments: the camera ray is segment 1.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["RussianRoulette", "POLICIES"]

POLICIES = ("off", "fixed", "albedo", "throughput")


@dataclass(frozen=True)
class RussianRoulette:
    """A roulette policy; see the module docstring."""

    policy: str = "throughput"
    start_depth: int = 5
    probability: float = 0.5
    cap: float = 1.0

    def __post_init__(self) -> None:
        if self.policy not in POLICIES:
            raise ValueError(f"rr: expected one of {POLICIES}, got {self.policy!r}")
        if not (isinstance(self.start_depth, (int, np.integer)) and self.start_depth >= 1):
            raise ValueError(f"rr_depth: expected an integer >= 1, got {self.start_depth!r}")
        if not (isinstance(self.probability, (int, float)) and 0.0 <= self.probability < 1.0):
            raise ValueError(f"rr_probability: expected a termination probability in [0, 1), got {self.probability!r}")
        if not (isinstance(self.cap, (int, float)) and 0.0 < self.cap <= 1.0):
            raise ValueError(f"rr_cap: expected a survival cap in (0, 1], got {self.cap!r}")

    def describe(self) -> str:
        """The policy in words."""
        if self.policy == "off":
            return "no Russian roulette"
        rule = {"fixed": f"termination probability {self.probability:g}",
                "albedo": "survival probability = albedo",
                "throughput": f"survival probability = max throughput, capped at {self.cap:g}"}[self.policy]
        return f"Russian roulette from depth {self.start_depth}: {rule}"

    def survival(self, depth: np.ndarray, throughput: np.ndarray, albedo: np.ndarray) -> np.ndarray | None:
        """Survival probabilities (N,) of paths whose next segment would be ``depth + 1``, or None (all survive).

        ``depth`` (N,) counts each path's segments so far, ``throughput`` (C, N)
        is the path throughput including this vertex's sample weight, ``albedo``
        (C, N) that sample weight.
        """
        if self.policy == "off" or depth.max(initial=0) < self.start_depth:
            return None
        if self.policy == "fixed":
            q = np.full(throughput.shape[1], 1.0 - self.probability)
        elif self.policy == "albedo":
            q = np.clip(albedo.max(axis=0), 0.0, 1.0)
        else:
            q = np.clip(throughput.max(axis=0), 0.0, self.cap)
        return np.where(depth >= self.start_depth, q, 1.0)
