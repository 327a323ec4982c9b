"""Fresnel reflectance of smooth interfaces (unpolarised light).

Dielectric: the exact formula for relative index eta = eta_t / eta_i
(pbrt-v4, FrDielectric).  Conductor: the exact formula with complex index
eta + i k (pbrt-v4, FrComplex), per channel.
"""
from __future__ import annotations

import numpy as np

__all__ = ["fresnel_dielectric", "fresnel_conductor"]


def fresnel_dielectric(cos_i: np.ndarray, eta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(reflectance F, cos of the transmitted angle) for cos_i >= 0 on the incident side; F = 1 at total internal reflection."""
    cos_i = np.clip(cos_i, 0.0, 1.0)
    sin2_t = (1.0 - cos_i * cos_i) / (eta * eta)
    tir = sin2_t >= 1.0
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin2_t))
    with np.errstate(divide="ignore", invalid="ignore"):
        r_parl = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
        r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
        f = 0.5 * (r_parl * r_parl + r_perp * r_perp)
    return np.where(tir, 1.0, np.nan_to_num(f, nan=1.0)), cos_t


def fresnel_conductor(cos_i: np.ndarray, eta: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Reflectance (C, N) for cos_i (N,) in [0, 1] and complex index eta + i k (C, N).  Undefined inputs (NaN
    cosines of failed samples, whose weight is zero anyway) and the 0 / 0 of grazing light on an index-matched
    metal give 1, the grazing limit."""
    cos_i = np.clip(np.nan_to_num(cos_i, nan=0.0), 0.0, 1.0)
    eta_c = eta + 1j * k
    sin2_i = 1.0 - cos_i * cos_i
    sin2_t = sin2_i / (eta_c * eta_c)
    cos_t = np.sqrt(1.0 - sin2_t)
    with np.errstate(divide="ignore", invalid="ignore"):
        r_parl = (eta_c * cos_i - cos_t) / (eta_c * cos_i + cos_t)
        r_perp = (cos_i - eta_c * cos_t) / (cos_i + eta_c * cos_t)
    return np.nan_to_num(0.5 * (np.abs(r_parl) ** 2 + np.abs(r_perp) ** 2), nan=1.0)
