"""Sampling triangles by solid angle: uniform directions over the spherical triangle they subtend.

Arvo, "Stratified Sampling of Spherical Triangles" (SIGGRAPH 1995), in the
form of pbrt-v4 (SampleSphericalTriangle).  The solid angle itself uses Van
Oosterom & Strackee's formula, tan(Omega / 2) = |a . (b x c)| / (1 + a.b +
b.c + c.a) for unit vectors a, b, c toward the vertices.  All float64.
"""
from __future__ import annotations

import numpy as np

__all__ = ["solid_angle", "sample_spherical_triangle"]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.stack((a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]))


def _angle_between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Angle between unit vectors, accurate for nearly parallel and nearly opposite ones."""
    return np.where(_dot(u, v) < 0,
                    np.pi - 2.0 * np.arcsin(np.minimum(1.0, 0.5 * np.sqrt(_dot(u + v, u + v)))),
                    2.0 * np.arcsin(np.minimum(1.0, 0.5 * np.sqrt(_dot(v - u, v - u)))))


def solid_angle(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Solid angle (N,) subtended at points ref (3, N) by triangles (p0, p1, p2), each (3, N)."""
    a, b, c = _unit(p0 - ref), _unit(p1 - ref), _unit(p2 - ref)
    numerator = np.abs(_dot(a, _cross(b, c)))
    denominator = 1.0 + _dot(a, b) + _dot(b, c) + _dot(c, a)
    return 2.0 * np.arctan2(numerator, denominator)


def sample_spherical_triangle(p0, p1, p2, ref, u) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions (3, N), uniform over the solid angle of each triangle seen from ref, and that solid angle.

    Inputs are float64 (3, N) arrays and (2, N) uniforms.  Lanes where the
    triangle is degenerate as seen from ref get NaN directions.
    """
    a, b, c = _unit(p0 - ref), _unit(p1 - ref), _unit(p2 - ref)
    with np.errstate(invalid="ignore", divide="ignore"):
        n_ab, n_bc, n_ca = _unit(_cross(a, b)), _unit(_cross(b, c)), _unit(_cross(c, a))
        alpha = _angle_between(n_ab, -n_ca)
        beta = _angle_between(n_bc, -n_ab)
        gamma = _angle_between(n_ca, -n_bc)
        area_pi = alpha + beta + gamma                 # spherical excess + pi
        sampled_pi = np.pi + u[0] * (area_pi - np.pi)  # a sub-triangle of area u0 * A
        cos_alpha, sin_alpha = np.cos(alpha), np.sin(alpha)
        sin_phi = np.sin(sampled_pi) * cos_alpha - np.cos(sampled_pi) * sin_alpha
        cos_phi = np.cos(sampled_pi) * cos_alpha + np.sin(sampled_pi) * sin_alpha
        k1 = cos_phi + cos_alpha
        k2 = sin_phi - sin_alpha * _dot(a, b)
        cos_bp = (k2 + (k2 * cos_phi - k1 * sin_phi) * cos_alpha) / ((k2 * sin_phi + k1 * cos_phi) * sin_alpha)
        cos_bp = np.clip(cos_bp, -1.0, 1.0)
        sin_bp = np.sqrt(np.maximum(0.0, 1.0 - cos_bp * cos_bp))
        c_perp = _unit(c - _dot(c, a) * a)
        c_prime = cos_bp * a + sin_bp * c_perp          # third vertex of the sub-triangle, on arc a-c
        cos_theta = 1.0 - u[1] * (1.0 - _dot(c_prime, b))
        sin_theta = np.sqrt(np.maximum(0.0, 1.0 - cos_theta * cos_theta))
        w = cos_theta * b + sin_theta * _unit(c_prime - _dot(c_prime, b) * b)
    return w, area_pi - np.pi
