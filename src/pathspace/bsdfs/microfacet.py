"""The GGX (Trowbridge-Reitz) microfacet distribution, isotropic, in local coordinates (z = normal).

D, the Smith masking term and sampling of the distribution of visible
normals follow Heitz, "Understanding the Masking-Shadowing Function" (JCGT
2014) and "Sampling the GGX Distribution of Visible Normals" (JCGT 2018).
All arrays are float64 (3, N) local vectors; ``alpha`` is (N,) roughness.
"""
from __future__ import annotations

import numpy as np

__all__ = ["ggx_d", "smith_lambda", "smith_g1", "smith_g2", "sample_visible_normal", "visible_normal_pdf"]


def ggx_d(h: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """D(h) = alpha^2 / (pi ((alpha^2 - 1) cos^2 + 1)^2) for h.z > 0, else 0."""
    a2 = alpha * alpha
    c2 = h[2] * h[2]
    denom = (a2 - 1.0) * c2 + 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        d = a2 / (np.pi * denom * denom)
    return np.where(h[2] > 0, d, 0.0)


def smith_lambda(w: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Lambda(w) = (sqrt(1 + alpha^2 tan^2 theta) - 1) / 2."""
    c2 = w[2] * w[2]
    s2 = np.maximum(0.0, 1.0 - c2)
    with np.errstate(divide="ignore", invalid="ignore"):
        t2 = np.where(c2 > 0, s2 / c2, np.inf)
    return 0.5 * (np.sqrt(1.0 + alpha * alpha * t2) - 1.0)


def smith_g1(w: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Masking of one direction, 1 / (1 + Lambda)."""
    return 1.0 / (1.0 + smith_lambda(w, alpha))


def smith_g2(wo: np.ndarray, wi: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Height-correlated masking-shadowing 1 / (1 + Lambda(wo) + Lambda(wi))."""
    return 1.0 / (1.0 + smith_lambda(wo, alpha) + smith_lambda(wi, alpha))


def sample_visible_normal(wo: np.ndarray, alpha: np.ndarray, u: np.ndarray) -> np.ndarray:
    """A microfacet normal distributed as D_wo(h) = G1(wo) max(0, wo.h) D(h) / wo.z (wo.z > 0)."""
    vh = np.stack((alpha * wo[0], alpha * wo[1], wo[2]))
    vh /= np.sqrt(vh[0] ** 2 + vh[1] ** 2 + vh[2] ** 2)
    lensq = vh[0] ** 2 + vh[1] ** 2
    inv = np.where(lensq > 0, 1.0 / np.sqrt(np.where(lensq > 0, lensq, 1.0)), 0.0)
    t1 = np.stack((np.where(lensq > 0, -vh[1] * inv, 1.0), np.where(lensq > 0, vh[0] * inv, 0.0), np.zeros_like(lensq)))
    t2 = np.stack((vh[1] * t1[2] - vh[2] * t1[1], vh[2] * t1[0] - vh[0] * t1[2], vh[0] * t1[1] - vh[1] * t1[0]))
    r = np.sqrt(u[0])
    phi = 2.0 * np.pi * u[1]
    p1 = r * np.cos(phi)
    p2 = r * np.sin(phi)
    s = 0.5 * (1.0 + vh[2])
    p2 = (1.0 - s) * np.sqrt(np.maximum(0.0, 1.0 - p1 * p1)) + s * p2
    p3 = np.sqrt(np.maximum(0.0, 1.0 - p1 * p1 - p2 * p2))
    nh = p1 * t1 + p2 * t2 + p3 * vh
    h = np.stack((alpha * nh[0], alpha * nh[1], np.maximum(1e-12, nh[2])))
    return h / np.sqrt(h[0] ** 2 + h[1] ** 2 + h[2] ** 2)


def visible_normal_pdf(wo: np.ndarray, h: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Density D_wo(h) of :func:`sample_visible_normal` over microfacet normals."""
    cos_oh = np.maximum(0.0, wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2])
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(wo[2] > 0, smith_g1(wo, alpha) * cos_oh * ggx_d(h, alpha) / wo[2], 0.0)
