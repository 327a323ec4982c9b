"""Every scattering model (diffuse, Phong, GGX conductor, mirror, glass): chi-square of its sampling,
sample/eval/pdf consistency, energy conservation, known albedos, reciprocity, parameter validation.
Glass-specific behaviour (Fresnel, Snell, dispersion) is in test_dielectric.py."""
from __future__ import annotations

import zlib

import numpy as np
import pytest

from pathspace.bsdfs import Conductor, Dielectric, Diffuse, MaterialLanes, MaterialTable, Mirror, Phong
from pathspace.bsdfs.base import Surface
from pathspace.spectra import RGBColours
from pathspace.validate.bsdf import BSDFCheck, bsdf_albedo, bsdf_chi2, bsdf_consistency

GOLD = dict(eta=(0.143, 0.374, 1.442), k=(3.983, 2.385, 1.603))


NONDELTA = {
    "diffuse-cosine": (Diffuse((0.8, 0.5, 0.2)), {}),
    "diffuse-uniform": (Diffuse((0.8, 0.5, 0.2)), {"diffuse_sampling": "uniform"}),
    "phong-e5": (Phong((0.4, 0.3, 0.2), (0.5, 0.6, 0.7), 5.0), {}),
    "phong-e80": (Phong((0.1, 0.1, 0.1), (0.8, 0.8, 0.8), 80.0), {}),
    "gold-0.05": (Conductor(alpha=0.05, **GOLD), {}),
    "gold-0.3": (Conductor(alpha=0.3, **GOLD), {}),
    "gold-1.0": (Conductor(alpha=1.0, **GOLD), {}),
}


WO = {"normal": (0, 0, 1), "45": (0.5, 0.5, 0.7071), "80": (0.985, 0, 0.174), "below": (0.3, -0.2, -0.93)}


CHI2_TESTS = len(NONDELTA) * len(WO)


@pytest.mark.parametrize("wo", WO.values(), ids=WO.keys())
@pytest.mark.parametrize("name", NONDELTA)
def test_sampling_matches_pdf_chi2(name, wo):
    material, options = NONDELTA[name]
    check = BSDFCheck(material, wo, options=options)
    result = bsdf_chi2(check, sample_count=400_000, seed=zlib.crc32(f"{name} {wo}".encode()) % 1000, test_count=CHI2_TESTS)
    assert result.passed, str(result)


@pytest.mark.parametrize("wo", WO.values(), ids=WO.keys())
@pytest.mark.parametrize("name", NONDELTA)
def test_sample_pdf_and_weight_agree_with_eval(name, wo):
    material, options = NONDELTA[name]
    result = bsdf_consistency(BSDFCheck(material, wo, options=options), sample_count=50_000)
    assert result.samples > 10_000
    assert result.ok(1e-4), result


@pytest.mark.parametrize("alpha", [1e-4, 1e-3, 1e-2])
def test_very_smooth_conductor_is_consistent(alpha):
    """Down to alpha = 1e-4 the GGX samples stay finite and consistent with eval (no chi-square at this peak)."""
    check = BSDFCheck(Conductor(alpha=alpha, **GOLD), (0.3, 0.1, 0.95))
    s = check.sample(np.random.default_rng(0).random((3, 20_000)))
    assert np.all(np.isfinite(s.weight)) and np.all(np.isfinite(s.pdf)) and np.all(np.isfinite(s.wi))
    result = bsdf_consistency(check, sample_count=20_000)
    assert result.ok(1e-3), result
    # Nearly a mirror: the samples cluster at the mirror direction, weights near the Fresnel reflectance.
    mirror = np.array([-0.3, -0.1, 0.95]) / np.linalg.norm([0.3, 0.1, 0.95])
    spread = np.degrees(np.arccos(np.clip(mirror @ s.wi.astype(np.float64), -1, 1)))
    assert np.median(spread) < 200 * alpha


@pytest.mark.parametrize("wo", WO.values(), ids=WO.keys())
@pytest.mark.parametrize("name", list(NONDELTA) + ["mirror", "glass"])
def test_energy_is_conserved(name, wo):
    """Directional albedo <= 1 in every channel (within 4 standard errors)."""
    material = {"mirror": Mirror((1.0, 1.0, 1.0)), "glass": Dielectric(1.5)}.get(name) or NONDELTA[name][0]
    options = NONDELTA[name][1] if name in NONDELTA else {}
    albedo, error = bsdf_albedo(BSDFCheck(material, wo, options=options, mode="importance"))
    assert np.all(albedo <= 1.0 + 4 * error + 1e-12), (albedo, error)


def test_known_albedos():
    """Diffuse: exactly the reflectance; Phong at normal incidence: kd + ks * (e+2)/(e+1) * ...; mirror: R."""
    albedo, error = bsdf_albedo(BSDFCheck(Diffuse((0.8, 0.5, 0.2)), (0.3, 0.4, 0.866)))
    np.testing.assert_allclose(albedo, [0.8, 0.5, 0.2], atol=1e-12)
    albedo, _ = bsdf_albedo(BSDFCheck(Mirror((0.9, 0.8, 0.7)), (0.3, 0.4, 0.866)))
    np.testing.assert_allclose(albedo, [0.9, 0.8, 0.7])
    # Glass in importance mode conserves energy exactly: reflect with F, refract with 1 - F, weights 1.
    albedo, error = bsdf_albedo(BSDFCheck(Dielectric(1.5), (0.6, 0.0, 0.8), mode="importance"))
    np.testing.assert_allclose(albedo, 1.0)
    # Phong at normal incidence: the glossy lobe about the normal is fully above the surface, so the albedo
    # is kd + ks * (e + 2) / (e + 1) * integral of cos^e cos / ... = kd + ks * (e + 2)/(e + 2) = kd + ks.
    albedo, error = bsdf_albedo(BSDFCheck(Phong((0.2, 0.2, 0.2), (0.7, 0.5, 0.3), 20.0), (0, 0, 1)))
    assert np.all(np.abs(albedo - [0.9, 0.7, 0.5]) < 4 * error + 1e-6), (albedo, error)


@pytest.mark.parametrize("name", ["phong-e5", "gold-0.3", "diffuse-cosine"])
def test_reciprocity(name):
    """f(wo, wi) |cos_o| ... : f(wo, wi) = f(wi, wo), checked through f_cos / |cos_i|."""
    material, options = NONDELTA[name]
    rng = np.random.default_rng(4)
    a = rng.normal(size=(3, 2000))
    b = rng.normal(size=(3, 2000))
    a[2], b[2] = np.abs(a[2]), np.abs(b[2])
    a /= np.linalg.norm(a, axis=0)
    b /= np.linalg.norm(b, axis=0)
    f_ab = [BSDFCheck(material, a[:, k], options=options).eval(b[:, k:k + 1])[0][:, 0] / b[2, k] for k in range(200)]
    f_ba = [BSDFCheck(material, b[:, k], options=options).eval(a[:, k:k + 1])[0][:, 0] / a[2, k] for k in range(200)]
    np.testing.assert_allclose(f_ab, f_ba, rtol=1e-4, atol=1e-9)


def test_material_validation():
    with pytest.raises(ValueError, match="reflectance"):
        Diffuse((0.5, 1.2, 0.5))
    with pytest.raises(ValueError, match="energy conservation"):
        Phong((0.6, 0.6, 0.6), (0.5, 0.3, 0.3), 10.0)
    with pytest.raises(ValueError, match="alpha: expected a GGX roughness in"):
        Conductor(alpha=2.0, **GOLD)
    with pytest.raises(ValueError, match="ior"):
        Dielectric(-1.0)


def test_material_lanes_of_several_kinds_and_their_non_specular_part():
    """A wavefront of mixed materials evaluates each lane with its own model, one of a single kind (among
    several in the scene) takes the one-kind path, and ``part`` gives the specular or non-specular lanes with the
    same values as the whole wavefront, through the parameters already gathered."""
    table = MaterialTable(["white", "glossy", "gold", "mirror", "glass"],
                          [Diffuse((0.2, 0.8, 0.4)), Phong((0.3, 0.3, 0.3), (0.5, 0.6, 0.2), 10.0),
                           Conductor(alpha=0.3, **GOLD), Mirror((1.0, 1.0, 1.0)), Dielectric(1.5)])
    rng = np.random.default_rng(8)
    count = 4000
    ids = rng.integers(0, 5, count)
    normal = np.tile(np.array([[0.0], [0.0], [1.0]], np.float32), count)
    direction = -rng.normal(size=(3, count)).astype(np.float32)
    direction[2] = -np.abs(direction[2])
    direction /= np.linalg.norm(direction, axis=0)
    surface = Surface.facing(normal, direction)
    wi = rng.normal(size=(3, count)).astype(np.float32)
    wi[2] = np.abs(wi[2])
    wi /= np.linalg.norm(wi, axis=0)
    options = {"diffuse_sampling": "cosine"}
    lanes = MaterialLanes(table, ids, RGBColours, options)
    f_cos, pdf = lanes.eval(surface, wi)
    for k in range(5):                 # each lane as if its material were alone
        one = np.flatnonzero(ids == k)
        alone = MaterialLanes(MaterialTable(["m"], [table.materials[k]]), np.zeros(one.size, np.int64), RGBColours,
                              options).eval(surface.take(one), wi[:, one])
        np.testing.assert_allclose(f_cos[:, one], alone[0], rtol=1e-12)
        np.testing.assert_allclose(pdf[one], alone[1], rtol=1e-12)
    assert (f_cos[:, ids >= 3] == 0).all()                              # delta materials: nothing off their lobes
    glossy = np.flatnonzero(ids == 1)
    single = MaterialLanes(table, ids.take(glossy), RGBColours, options)
    assert len(single.groups) == 1 and single.groups[0][1] is None
    np.testing.assert_allclose(single.eval(surface.take(glossy), wi[:, glossy])[0], f_cos[:, glossy], rtol=1e-12)
    todo, part = lanes.part(specular=False)
    np.testing.assert_array_equal(todo, np.flatnonzero(ids < 3))
    assert len(part.groups) == 3 and part.count == todo.size
    part_f, part_pdf = part.eval(surface.take(todo), wi[:, todo])
    np.testing.assert_allclose(part_f, f_cos[:, todo], rtol=1e-12)
    np.testing.assert_allclose(part_pdf, pdf[todo], rtol=1e-12)
    todo, part = single.part(specular=False)
    np.testing.assert_array_equal(todo, np.arange(glossy.size))
    assert part.groups[0][1] is None
    specular = MaterialLanes(table, np.array([3, 4, 4, 3]), RGBColours, options)
    todo, part = specular.part(specular=False)
    assert todo.size == 0 and part.groups == [] and part.count == 0
    no_delta = MaterialTable(["white", "glossy"], table.materials[:2])
    both = MaterialLanes(no_delta, ids % 2, RGBColours, options)
    todo, part = both.part(specular=False)
    np.testing.assert_array_equal(todo, np.arange(count))
    np.testing.assert_allclose(part.eval(surface, wi)[0], both.eval(surface, wi)[0], rtol=0)
    todo, part = lanes.part(specular=True)                              # the mirror and glass lanes
    np.testing.assert_array_equal(todo, np.flatnonzero(ids >= 3))
    assert len(part.groups) == 2 and part.delta.all()
    u = rng.random((3, count))
    whole, alone = lanes.sample(surface, u), part.sample(surface.take(todo), u[:, todo])
    np.testing.assert_array_equal(alone.wi, whole.wi[:, todo])
    np.testing.assert_array_equal(alone.weight, whole.weight[:, todo])
    np.testing.assert_array_equal(alone.pdf, whole.pdf[todo])
