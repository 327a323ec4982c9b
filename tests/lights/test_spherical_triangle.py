"""Uniform sampling of the solid angle a triangle subtends (Arvo 1995): chi-square against 1 / Omega
inside the spherical triangle."""
from __future__ import annotations

import numpy as np

from pathspace.lights.spherical_triangle import sample_spherical_triangle, solid_angle
from pathspace.validate import chi2_test_directions


def test_solid_angle_sampling_is_uniform_over_the_triangle_chi2():
    v = np.array([[-0.3, 0.2, -1.0], [0.6, 0.1, -0.8], [0.1, 0.9, -1.2]])
    ref = np.zeros((3, 1))
    omega = float(solid_angle(v[0][:, None], v[1][:, None], v[2][:, None], ref)[0])

    def sample(u):
        count = u.shape[1]
        rep = [np.repeat(x[:, None], count, axis=1) for x in v]
        w, _ = sample_spherical_triangle(*rep, np.zeros((3, count)), u)
        return w, np.all(np.isfinite(w), axis=0)

    def pdf(w):
        # Inside the spherical triangle iff the ray hits the planar triangle.
        e1, e2 = v[1] - v[0], v[2] - v[0]
        s1 = np.cross(w.T, e2)
        det = s1 @ e1
        b1 = (-(v[0]) @ s1.T) / det
        b2 = np.einsum("ij,ij->i", w.T, np.cross(-v[0], e1)[None, :].repeat(w.shape[1], 0)) / det
        t = (np.cross(-v[0], e1) @ e2) / det
        tolerance = 1e-6  # directions along the edges, within float rounding of inside
        inside = (b1 >= -tolerance) & (b2 >= -tolerance) & (b1 + b2 <= 1 + tolerance) & (t > 0)
        return np.where(inside, 1.0 / omega, 0.0)

    result = chi2_test_directions(sample, pdf, sample_count=300_000, res_z=64, res_phi=128, seed=3)
    assert result.passed, str(result)

