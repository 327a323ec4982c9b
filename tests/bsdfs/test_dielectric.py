"""The dielectric (glass): reflection with the Fresnel probability, Snell's law, radiance scaled by 1/eta^2
on refraction, total internal reflection; with a Cauchy law, dispersion that deviates short wavelengths
most and terminates the secondary wavelengths of a spectral lane."""
from __future__ import annotations

import numpy as np

from pathspace import spectra
from pathspace.bsdfs import Dielectric, Surface
from pathspace.spectra import Cauchy, SpectralColours
from pathspace.validate.bsdf import BSDFCheck, fresnel_dielectric_albedo


def test_glass_fresnel_and_radiance_scaling():
    """Reflection probability follows the Fresnel equations; refraction into glass scales radiance by 1/eta^2."""
    for cos_o, eta in ((1.0, 1.5), (0.5, 1.5), (0.2, 1.33)):
        wo = (np.sqrt(1 - cos_o ** 2), 0.0, cos_o)
        s = BSDFCheck(Dielectric(eta), wo).sample(np.random.default_rng(1).random((3, 200_000)))
        reflected = s.wi[2] > 0
        expected = fresnel_dielectric_albedo(cos_o, eta)
        assert abs(reflected.mean() - expected) < 4 * np.sqrt(expected * (1 - expected) / reflected.size)
        np.testing.assert_allclose(s.weight[:, ~reflected], 1.0 / eta ** 2)
        np.testing.assert_allclose(s.weight[:, reflected], 1.0)
        # Snell's law: sin_t = sin_o / eta.
        sin_t = np.hypot(s.wi[0, ~reflected], s.wi[1, ~reflected])
        np.testing.assert_allclose(sin_t, np.sqrt(1 - cos_o ** 2) / eta, atol=1e-6)
    # From inside, beyond the critical angle, everything reflects.
    s = BSDFCheck(Dielectric(1.5), (0.9, 0.0, -0.436)).sample(np.random.default_rng(2).random((3, 1000)))
    assert np.all(s.wi[2] < 0)



def test_dispersion_separates_wavelengths_in_order():
    """Through a prism (two refractions of a Cauchy glass), shorter wavelengths are deviated more."""
    glass = Dielectric(Cauchy(1.6, 0.01))
    wavelengths = np.linspace(400, 700, 16)
    # Enter one face of a 60-degree prism at 55 degrees from its normal, leave through the other face.
    n1 = np.array([0.0, 0.0, 1.0])
    n2 = np.array([np.sin(np.radians(60)), 0.0, -np.cos(np.radians(60))])  # outward normal of the exit face
    incoming = np.array([np.sin(np.radians(55)), 0.0, -np.cos(np.radians(55))])
    exits = []
    for lam in wavelengths:
        colours = SpectralColours(np.full((4, 1), lam), *spectra.grid_position(np.full((4, 1), lam)))
        params = Dielectric.gather(Dielectric.tables([glass]), np.zeros(1, dtype=np.int64), colours, {})
        inside = Dielectric.sample(params, Surface.facing(n1[:, None].astype(np.float32),
                                                          incoming[:, None].astype(np.float32)),
                                   np.full((3, 1), 0.9999)).wi
        out = Dielectric.sample(params, Surface.facing(n2[:, None].astype(np.float32), inside),
                                np.full((3, 1), 0.9999))
        assert out.weight[0, 0] > 0 and np.all(out.weight[1:, 0] == 0) and out.terminated[0]  # secondaries terminated
        assert n2 @ out.wi[:, 0] > 0  # refracted out of the prism (no total internal reflection)
        exits.append(np.degrees(np.arccos(np.clip(incoming @ out.wi[:, 0].astype(np.float64), -1, 1))))
    deviation = np.array(exits)
    assert np.all(np.diff(deviation) < 0)      # blue (400 nm) deviated most, red least
    assert deviation[0] - deviation[-1] > 1.0  # by more than a degree for this flint glass

