"""Every sampling routine of the package through the chi-square harness (pathspace.validate.chi2), over its own
domain: directions on the sphere (warps, BSDFs, GGX visible normals, lights, lens and film directions; zoomed
onto narrow lobes: Phong 1000, GGX alpha 0.01, a light's spherical triangle, a small spot cone, a far lens),
points of a triangle, of a lens disk, of a light's ray disk, of the film, and hero wavelengths.  Where the support of a density is known it is given, so that its edges are integrated exactly and
samples near them are not mistaken for strays; grazing configurations are included in every family.

The harness is checked both ways: exact control samplers (inverse CDFs of densities whose cell integrals are
known in closed form) pass, and planted bugs fail -- a density 5% too high, a Phong exponent 5% off between
sampler and density, a GGX roughness 5% off, a cone 5% too wide, a sample outside the support.

Delta lobes (mirror, smooth glass) and delta lights' positions have no density to test; their directional
or positional densities, where they have one (spot and point emission, the rays of lights at infinity), are.
Each parametrised family shares a Sidak-corrected family-wise significance of 1%.
"""
from __future__ import annotations

import numpy as np
import pytest

from pathspace import warp
from pathspace.bsdfs import Conductor, Diffuse, Phong, Surface
from pathspace.bsdfs.microfacet import sample_visible_normal, visible_normal_pdf
from pathspace.camera import PinholeCamera, ThinLensCamera
from pathspace.lights import AreaLight, DirectionalLight, Environment, PointLight, SpotLight
from pathspace.lights.base import LightContext, disk_origins
from pathspace.scene.mesh import TriangleMesh
from pathspace.spectra import LAMBDA_MAX, LAMBDA_MIN, WAVELENGTH_SAMPLING, RGBColours, sample_wavelengths, wavelength_pdf
from pathspace.validate import PlaneDomain, SphereDomain, Support, chi2_test, sidak_significance
from pathspace.validate.bsdf import BSDFCheck
from pathspace.vecmath import orthonormal_basis

ALPHA = 0.01  # family-wise significance of every parametrised family (chi2_test's default alpha)
GOLD = dict(eta=(0.143, 0.374, 1.442), k=(3.983, 2.385, 1.603))


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def check(result, passed: bool = True) -> None:
    """Assert the outcome, printing the report either way."""
    print(result)
    assert result.passed is passed, str(result)


def repeat(v: np.ndarray, count: int) -> np.ndarray:
    return np.repeat(np.asarray(v)[:, None], count, axis=1)


def zoom(centre, angle: float, away=(0.0, 0.0, 1.0), offset: float = 0.05) -> SphereDomain:
    """A cap holding the directions within ``angle`` of ``centre``, its pole ``offset`` radians off the centre
    toward ``away`` (or any perpendicular): the pole of (cos theta, phi) cells is a coordinate singularity,
    and a narrow ridge through it (a GGX lobe at grazing incidence, a sliver of a triangle) would cost the
    quadrature ten times more refinement."""
    centre = unit(centre)
    side = np.asarray(away, dtype=np.float64) - (np.asarray(away) @ centre) * centre
    if np.linalg.norm(side) < 1e-6:
        side = orthonormal_basis(centre[:, None])[0][:, 0]
    axis = np.cos(offset) * centre + np.sin(offset) * unit(side)
    return SphereDomain(axis, min(np.pi, angle + offset))


# -- warps ------------------------------------------------------------------------------------------------

NORMALS = {"up": (0.0, 0.0, 1.0), "tilted": (0.3, -0.5, 0.8), "down": (0.0, 0.0, -1.0),
           "nearly-horizontal": (1.0, 0.2, 1e-3)}


def test_uniform_sphere_warp():
    result = chi2_test(SphereDomain(), warp.square_to_uniform_sphere, warp.square_to_uniform_sphere_pdf,
                       sample_count=500_000, seed=1)
    check(result)


@pytest.mark.parametrize("normal", NORMALS.values(), ids=NORMALS.keys())
def test_cosine_warp_about_a_normal(normal):
    """square_to_cosine_about: max(cos, 0) / pi about n, on the hemisphere of n (exact edge)."""
    n = unit(normal)

    def sample(u):
        return warp.square_to_cosine_about(repeat(n.astype(np.float32), u.shape[1]), u)

    def pdf(w):
        return np.maximum(n @ w, 0.0) / np.pi

    result = chi2_test(SphereDomain(), sample, pdf, support=Support.hemisphere(n), sample_count=500_000,
                       seed=2, test_count=len(NORMALS))
    check(result)


def test_uniform_triangle_warp_in_its_barycentric_domain():
    """square_to_uniform_triangle: (b1, b2) uniform on the triangle b1, b2 >= 0, b1 + b2 <= 1 (density 2)."""
    def sample(u):
        return np.stack(warp.square_to_uniform_triangle(u))

    def pdf(b):
        return np.where((b[0] >= 0) & (b[1] >= 0) & (b[0] + b[1] <= 1), 2.0, 0.0)

    result = chi2_test(PlaneDomain.unit_square(), sample, pdf, support=Support.triangle(), sample_count=500_000,
                       seed=3)
    check(result)
    assert abs(result.pdf_integral - 1) < 1e-12


# -- BSDFs ------------------------------------------------------------------------------------------------

WO = {"normal": (0.0, 0.0, 1.0), "45": (0.5, 0.5, 0.7071), "grazing-85": (0.996, 0.0, 0.0872),
      "grazing-89": (0.99985, 0.0, 0.01745)}
WIDE = {"diffuse-cosine": (Diffuse((0.8, 0.5, 0.2)), {}),
        "diffuse-uniform": (Diffuse((0.8, 0.5, 0.2)), {"diffuse_sampling": "uniform"}),
        "phong-e5": (Phong((0.4, 0.3, 0.2), (0.5, 0.6, 0.7), 5.0), {}),
        "phong-e80": (Phong((0.1, 0.1, 0.1), (0.8, 0.8, 0.8), 80.0), {}),
        "ggx-0.5": (Conductor(alpha=0.5, **GOLD), {})}
# Narrow lobes, tested on a cap about the mirror direction (radians): cells fine where the mass is.
NARROW = {"phong-e1000": (Phong((0.02, 0.02, 0.02), (0.9, 0.9, 0.9), 1000.0), 0.2),
          "ggx-0.01": (Conductor(alpha=0.01, **GOLD), 0.15)}


def mirror(wo) -> np.ndarray:
    wo = unit(wo)
    return 2 * wo[2] * np.array([0.0, 0.0, 1.0]) - wo


def bsdf_routines(bsdf: BSDFCheck):
    """(sample, pdf) of a model's sampling at a fixed wo: the model's own sample and eval.  The density is
    evaluated at float64 directions (BSDFCheck.eval rounds them to float32, which makes a lobe 0.01 rad wide
    noisy at the 1e-5 level and stalls the adaptive quadrature)."""
    def sample(u):
        s = bsdf.sample(u)
        return s.wi, s.pdf > 0

    def pdf(w):
        count = w.shape[1]
        params = bsdf.table.gather(0, np.zeros(count, dtype=np.int64), RGBColours, bsdf.options)
        normal = repeat(bsdf.normal.astype(np.float32), count)
        return bsdf.model.eval(params, Surface.facing(normal, -repeat(bsdf.wo.astype(np.float32), count)), w)[1]

    return sample, pdf


@pytest.mark.parametrize("wo", WO.values(), ids=WO.keys())
@pytest.mark.parametrize("name", WIDE)
def test_bsdf_sampling_over_the_sphere(name, wo):
    material, options = WIDE[name]
    sample, pdf = bsdf_routines(BSDFCheck(material, wo, options=options))
    result = chi2_test(SphereDomain(), sample, pdf, support=Support.hemisphere((0, 0, 1)), dims=3,
                       sample_count=400_000, seed=len(name) + int(100 * wo[2]), test_count=len(WIDE) * len(WO))
    check(result)


@pytest.mark.parametrize("wo", WO.values(), ids=WO.keys())
@pytest.mark.parametrize("name", NARROW)
def test_narrow_lobe_on_a_zoomed_cap(name, wo):
    """Phong 1000 and GGX alpha 0.01 on a cap about the mirror direction; at grazing wo the lobe is cut by
    the horizon (samples below it are invalid; the harness expects exactly what the density leaves out)."""
    material, angle = NARROW[name]
    sample, pdf = bsdf_routines(BSDFCheck(material, wo))
    domain = zoom(mirror(wo), angle)
    result = chi2_test(domain, sample, pdf, support=Support.hemisphere((0, 0, 1)), dims=3, sample_count=500_000,
                       seed=7 + int(100 * wo[2]), test_count=len(NARROW) * len(WO))
    check(result)
    assert result.outside_domain > 0  # the domain is zoomed: some mass (diffuse, tails) lies beyond it


@pytest.mark.parametrize("wo", WO.values(), ids=WO.keys())
@pytest.mark.parametrize("alpha", [0.5, 0.05])
def test_ggx_visible_normals(alpha, wo):
    """sample_visible_normal against visible_normal_pdf (Heitz 2018), over microfacet normals facing both the
    normal and wo (the support of D_wo): the routine under the conductor's sampling, on its own."""
    lo = unit(wo)
    a = np.array([alpha])

    def sample(u):
        count = u.shape[1]
        return sample_visible_normal(repeat(lo, count), np.full(count, alpha), u)

    def pdf(h):
        return visible_normal_pdf(repeat(lo, h.shape[1]), h, a)

    domain = SphereDomain() if alpha > 0.1 else zoom((0.0, 0.0, 1.0), 0.6, away=(1.0, 0.0, 0.0))
    support = Support.hemisphere((0, 0, 1)) & Support.hemisphere(lo)
    result = chi2_test(domain, sample, pdf, support=support, sample_count=400_000, seed=5 + int(100 * wo[2]),
                       test_count=2 * len(WO))
    check(result)


# -- area lights: solid-angle and area sampling of a triangle seen from a receiver -------------------------

def triangle_light(vertices, two_sided: bool = False):
    """Area-light tables of one emitting triangle (vertices (3, 3), rows are vertices)."""
    mesh = TriangleMesh(np.asarray(vertices, dtype=np.float64), np.array([[0, 1, 2]]), np.zeros(1, np.int32),
                        np.zeros(1, np.int32))
    context = LightContext(mesh, 10.0, np.zeros(3), 10.0)
    return AreaLight.tables([AreaLight((1.0, 1.0, 1.0), two_sided, np.array([0]))], context)


def stored_vertices(tables) -> np.ndarray:
    """The triangle as the light samples it: float32 rows p0, e1, e2 (vertices (3, 3), rows are vertices)."""
    rows = tables.table[:, 0].astype(np.float64)
    p0 = rows[0:3]
    return np.stack((p0, p0 + rows[3:6], p0 + rows[6:9]))


TRIANGLES = {
    # name: (vertices, receiver)
    "overhead": ([[-0.5, 1.0, -0.4], [0.6, 1.1, -0.3], [0.0, 0.9, 0.7]], [0.1, 0.0, 0.2]),
    "large-near": ([[-3.0, 0.5, -3.0], [3.0, 0.5, -3.0], [0.0, 0.5, 4.0]], [0.2, 0.0, 0.1]),
    "grazing-1e-2": ([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], [1.5, 0.01, 1.2]),
    "grazing-1e-3": ([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], [1.5, 1e-3, 1.2]),
    "grazing-below": ([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], [-0.8, -0.02, 0.4]),
    "sliver": ([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 0.0, 0.01]], [0.3, 0.5, 0.2]),
    "sliver-grazing": ([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 0.003, 0.01]], [0.4, 0.05, -0.6]),
}
MEASURES = ("solid_angle", "area")


def triangle_case(name: str):
    """(tables, receiver, vertices as stored, the domain: a cap about the triangle's directions)."""
    vertices, receiver = TRIANGLES[name]
    tables = triangle_light(vertices)
    receiver = np.asarray(receiver, dtype=np.float32).astype(np.float64)
    stored = stored_vertices(tables)
    d = stored - receiver
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    axis = unit(d.sum(axis=0))
    angle = 1.1 * float(np.arccos(np.clip(d @ axis, -1, 1)).max()) + 1e-3
    return tables, receiver, stored, zoom(axis, angle, away=tables.table[9:12, 0])


def triangle_direction_pdf(tables, receiver: np.ndarray, stored: np.ndarray, measure: str):
    """The light's own solid-angle density (pdf_li) of directions: where a direction meets the triangle."""
    p0, e1, e2 = stored[0], stored[1] - stored[0], stored[2] - stored[0]
    normal = unit(np.cross(e1, e2))

    def pdf(w):
        count = w.shape[1]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (normal @ (p0 - receiver)) / (normal @ w)
        point = receiver[:, None] + w * t
        q = point - p0[:, None]
        # barycentrics of the point in the plane (least squares on the two edges)
        gram = np.array([[e1 @ e1, e1 @ e2], [e1 @ e2, e2 @ e2]])
        b1, b2 = np.linalg.solve(gram, np.stack((e1 @ q, e2 @ q)))
        inside = np.isfinite(t) & (t > 0) & (b1 >= 0) & (b2 >= 0) & (b1 + b2 <= 1)
        value = AreaLight.pdf_li(tables, np.zeros(count, np.int64), repeat(receiver, count),
                                 np.where(inside, point, p0[:, None]), measure)
        return np.where(inside, value, 0.0)

    return pdf


@pytest.mark.parametrize("measure", MEASURES)
@pytest.mark.parametrize("name", TRIANGLES)
def test_area_light_sample_li(name, measure):
    """sample_li's directions against pdf_li, on a cap holding the spherical triangle, with the spherical
    triangle as the support; grazing receivers (1e-2 and 1e-3 above the triangle's plane, and below it)
    see slivers a few 1e-3 rad thin, as do receivers of sliver triangles."""
    tables, receiver, stored, domain = triangle_case(name)

    def sample(u):
        count = u.shape[1]
        s = AreaLight.sample_li(tables, np.zeros(count, np.int64), repeat(receiver.astype(np.float32), count), u,
                                RGBColours, measure)
        return s.wi, s.pdf > 0

    pdf = triangle_direction_pdf(tables, receiver, stored, measure)
    result = chi2_test(domain, sample, pdf, support=Support.polygon_seen_from(receiver, stored),
                       sample_count=400_000, seed=11 + len(name), test_count=len(TRIANGLES) * len(MEASURES))
    check(result)
    assert result.outside_domain == 0 and result.outside == 0


def test_area_light_points_in_the_triangle():
    """The points sample_li finds (area measure) are uniform on the triangle: density 1 / area in the
    triangle's plane coordinates, with the triangle as support."""
    tables, receiver, stored, _ = triangle_case("overhead")
    p0, e1, e2 = stored[0], stored[1] - stored[0], stored[2] - stored[0]
    x_axis = unit(e1)
    y_axis = unit(e2 - (e2 @ x_axis) * x_axis)
    corners = np.stack([[(v - p0) @ x_axis, (v - p0) @ y_axis] for v in stored])

    def sample(u):
        count = u.shape[1]
        s = AreaLight.sample_li(tables, np.zeros(count, np.int64), repeat(receiver.astype(np.float32), count), u,
                                RGBColours, "area")
        q = s.point.astype(np.float64) - p0[:, None]
        return np.stack((x_axis @ q, y_axis @ q))

    area = float(tables.area[0])
    domain = PlaneDomain((corners[:, 0].min(), corners[:, 0].max()), (corners[:, 1].min(), corners[:, 1].max()))
    result = chi2_test(domain, sample, lambda p: np.full(p.shape[1], 1.0 / area), support=Support.polygon(corners),
                       sample_count=400_000, seed=12)
    check(result)


@pytest.mark.parametrize("two_sided", [False, True], ids=["one-sided", "two-sided"])
def test_area_light_emission_directions(two_sided):
    """sample_le: cosine-weighted about the normal (either side, half each, for two-sided lights)."""
    tables = triangle_light([[0.0, 0.0, 0.0], [1.0, 0.2, 0.0], [0.3, 0.1, 1.0]], two_sided)
    normal = tables.table[9:12, 0].astype(np.float64)

    def sample(u):
        count = u.shape[1]
        return AreaLight.sample_le(tables, np.zeros(count, np.int64), u, RGBColours, None).direction

    def pdf(w):
        count = w.shape[1]
        return AreaLight.pdf_le(tables, np.zeros(count, np.int64), repeat(normal, count), w, None)[1]

    support = None if two_sided else Support.hemisphere(normal)
    result = chi2_test(SphereDomain(), sample, pdf, support=support, dims=4, sample_count=500_000, seed=13,
                       test_count=2)
    check(result)


# -- spot, point and infinite lights ---------------------------------------------------------------------

CONES = (2.0, 30.0, 89.0, 90.0)
NO_CONTEXT = LightContext(None, 1.0, np.zeros(3), 1.0)


def spot_routines(cone: float, pdf_cone: float | None = None):
    """(tables, sample, pdf, light) of a spot light's emitted directions (pdf_le), the pdf possibly of
    another cone."""
    spot = SpotLight((0.1, 0.2, 0.3), (0.4, -1.0, 0.2), (1.0, 1.0, 1.0), cone, 0.8 * cone)
    tables = SpotLight.tables([spot], NO_CONTEXT)
    other = tables if pdf_cone is None else SpotLight.tables(
        [SpotLight(spot.position, spot.look_at, spot.intensity, pdf_cone, 0.8 * pdf_cone)], NO_CONTEXT)

    def sample(u):
        return SpotLight.sample_le(tables, np.zeros(u.shape[1], np.int64), u, RGBColours, NO_CONTEXT).direction

    def pdf(w):
        count = w.shape[1]
        return SpotLight.pdf_le(other, np.zeros(count, np.int64), np.zeros_like(w), w, NO_CONTEXT)[1]

    return sample, pdf, spot


@pytest.mark.parametrize("cone", CONES)
def test_spot_emission_in_its_cone(cone):
    """Directions uniform in the cone, on a cap slightly larger than the cone, the cone as the support:
    samples on the cone's edge are not strays."""
    sample, pdf, spot = spot_routines(cone)
    domain = SphereDomain(spot.axis, min(np.pi, 1.2 * np.radians(cone)))
    result = chi2_test(domain, sample, pdf, support=Support.cone(spot.axis, np.radians(cone)), dims=4,
                       sample_count=500_000, seed=int(cone), test_count=len(CONES))
    check(result)
    assert abs(result.pdf_integral - 1) < 1e-9


def test_point_light_emission():
    tables = PointLight.tables([PointLight((0.0, 1.0, 0.0), (1.0, 1.0, 1.0))], NO_CONTEXT)

    def sample(u):
        return PointLight.sample_le(tables, np.zeros(u.shape[1], np.int64), u, RGBColours, NO_CONTEXT).direction

    def pdf(w):
        count = w.shape[1]
        return PointLight.pdf_le(tables, np.zeros(count, np.int64), np.zeros_like(w), w, NO_CONTEXT)[1]

    check(chi2_test(SphereDomain(), sample, pdf, dims=4, sample_count=300_000, seed=21))


def test_environment_sample_li():
    tables = Environment.tables([Environment((0.5, 0.5, 0.5))], NO_CONTEXT)
    receiver = np.array([0.1, 0.2, 0.3])

    def sample(u):
        count = u.shape[1]
        return Environment.sample_li(tables, np.zeros(count, np.int64), repeat(receiver, count), u, RGBColours,
                                     "area").wi

    def pdf(w):
        count = w.shape[1]
        return Environment.pdf_li(tables, np.zeros(count, np.int64), repeat(receiver, count), w, "area")

    check(chi2_test(SphereDomain(), sample, pdf, sample_count=300_000, seed=22))


RAY_DISK = LightContext(None, 2.0, np.array([0.5, -0.2, 1.0]), 2.5)


def test_directional_light_ray_origins_on_the_disk():
    """Rays of a light at infinity start uniformly on a disk facing their direction: density 1 / (pi r^2)
    (pdf_le's positional part) in the disk's plane, the disk as the support."""
    tables = DirectionalLight.tables([DirectionalLight((0.3, -1.0, 0.2), (1.0, 1.0, 1.0))], RAY_DISK)
    d = tables.travel[:, 0].astype(np.float32).astype(np.float64)
    s, t = orthonormal_basis(d[:, None])
    centre = RAY_DISK.disk_center - d * RAY_DISK.disk_radius
    radius = RAY_DISK.disk_radius

    def sample(u):
        count = u.shape[1]
        e = DirectionalLight.sample_le(tables, np.zeros(count, np.int64), u, RGBColours, RAY_DISK)
        q = e.point.astype(np.float64) - centre[:, None]
        return np.stack((s[:, 0] @ q, t[:, 0] @ q))

    def pdf(p):
        count = p.shape[1]
        density = DirectionalLight.pdf_le(tables, np.zeros(count, np.int64), None, None, RAY_DISK)[1]
        return np.where(p[0] ** 2 + p[1] ** 2 <= radius ** 2, density, 0.0)

    result = chi2_test(PlaneDomain.around_disk(radius), sample, pdf, support=Support.disk(radius), dims=4,
                       sample_count=400_000, seed=23)
    check(result)


def test_environment_emission_directions_and_origins():
    """Environment sample_le: uniform directions (1 / (4 pi)) and, in each direction's disk, uniform origins."""
    tables = Environment.tables([Environment((0.5, 0.5, 0.5))], RAY_DISK)
    radius = RAY_DISK.disk_radius
    count = 400_000
    u = np.random.default_rng(24).random((4, count))
    e = Environment.sample_le(tables, np.zeros(count, np.int64), u, RGBColours, RAY_DISK)
    direction_pdf, origin_pdf = Environment.pdf_le(tables, np.zeros(1, np.int64), None, None, RAY_DISK)
    d = e.direction.astype(np.float64)
    s, t = orthonormal_basis(d)
    q = e.point.astype(np.float64) - (RAY_DISK.disk_center[:, None] - d * radius)
    origins = np.stack(((s * q).sum(axis=0), (t * q).sum(axis=0)))
    check(chi2_test(SphereDomain(), lambda _: e.direction, lambda w: np.full(w.shape[1], direction_pdf[0]),
                    dims=1, sample_count=count, test_count=2))
    check(chi2_test(PlaneDomain.around_disk(radius), lambda _: origins,
                    lambda p: np.where(p[0] ** 2 + p[1] ** 2 <= radius ** 2, origin_pdf[0], 0.0),
                    support=Support.disk(radius), dims=1, sample_count=count, test_count=2))


def test_disk_origins_fixed_direction():
    """disk_origins on its own, for a direction along -z (a disk in the xy plane)."""
    d = np.array([0.0, 0.0, -1.0])
    radius = RAY_DISK.disk_radius
    centre = RAY_DISK.disk_center - d * radius

    def sample(u):
        p = disk_origins(RAY_DISK, repeat(d, u.shape[1]), u)
        return p[:2] - centre[:2, None]

    result = chi2_test(PlaneDomain.around_disk(radius), sample,
                       lambda p: np.where(p[0] ** 2 + p[1] ** 2 <= radius ** 2, 1 / (np.pi * radius ** 2), 0.0),
                       support=Support.disk(radius), sample_count=300_000, seed=25)
    check(result)


# -- cameras: the lens disk, lens points seen from a receiver, film directions and positions ----------------

THIN_LENS = ThinLensCamera([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0], 60.0, 40, 30, aperture_radius=0.2,
                           focus_distance=3.0)
PINHOLE = PinholeCamera([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0], 60.0, 40, 30)


def test_thin_lens_points_on_the_disk():
    """sample_lens: uniform on the lens disk (1 / lens_area) in the lens plane's (right, up) coordinates."""
    camera = THIN_LENS

    def sample(u):
        q = camera.sample_lens(u) - camera.position[:, None]
        return np.stack((camera.right @ q, camera.image_up @ q))

    radius = camera.lens_radius
    result = chi2_test(PlaneDomain.around_disk(radius), sample,
                       lambda p: np.where(p[0] ** 2 + p[1] ** 2 <= radius ** 2, 1 / camera.lens_area, 0.0),
                       support=Support.disk(radius), sample_count=400_000, seed=31)
    check(result)
    assert abs(result.pdf_integral - 1) < 1e-12


def lens_direction_pdf(camera: ThinLensCamera, receiver: np.ndarray):
    """Solid-angle density at ``receiver`` of directions toward uniform lens points: d^2 / (|cos| A) on the
    lens disk."""
    n = camera.forward

    def pdf(w):
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (n @ (camera.position - receiver)) / (n @ w)
            point = receiver[:, None] + w * t - camera.position[:, None]
            on_lens = (t > 0) & ((point * point).sum(axis=0) <= camera.lens_radius ** 2)
            return np.where(on_lens, t * t / (np.abs(n @ w) * camera.lens_area), 0.0)

    return pdf


LENS_RECEIVERS = {"on-axis-far": (0.0, 0.0, 3.0), "off-axis": (0.3, -0.2, 1.0), "near": (0.1, 0.05, 0.5),
                  "grazing": (1.0, 0.3, 0.02), "far-grazing": (-3.0, 1.0, 0.05)}


@pytest.mark.parametrize("name", LENS_RECEIVERS)
def test_thin_lens_sample_importance_directions(name):
    """sample_importance: directions from a receiver toward uniform lens points, against d^2 / (|cos| A)
    (which must also be the density it reports), on a cap about the lens, the disk seen from the receiver
    (an oblique cone) as the support -- exactly integrated, so the densities integrate to 1 (the quadrature
    without a support reached 1.004 on axis)."""
    camera = THIN_LENS
    receiver = np.asarray(LENS_RECEIVERS[name], dtype=np.float64)
    pdf = lens_direction_pdf(camera, receiver)

    def sample(u):
        wi, _, reported, _, _, _ = camera.sample_importance(repeat(receiver, u.shape[1]), u)
        np.testing.assert_allclose(reported, pdf(wi.astype(np.float64)), rtol=1e-6)
        return wi

    to_lens = camera.position - receiver
    angle = min(np.pi, 1.3 * np.arctan2(camera.lens_radius, np.linalg.norm(to_lens)) + 0.05)
    support = Support.disk_seen_from(receiver, camera.position, camera.forward, camera.lens_radius)
    result = chi2_test(zoom(to_lens, angle, away=camera.forward), sample, pdf, support=support, sample_count=400_000,
                       seed=32 + len(name), test_count=len(LENS_RECEIVERS))
    check(result)
    assert abs(result.pdf_integral - 1) < 1e-7


def film_corners(camera, lens_point: np.ndarray) -> np.ndarray:
    """The film rectangle as seen from a lens point: the corners of the focal rectangle (distance 1 for a
    pinhole), rows are corners."""
    distance = getattr(camera, "focus_distance", 1.0)
    tx, ty = camera.tan_half
    return np.stack([camera.position + distance * (camera.forward + a * tx * camera.right + b * ty * camera.image_up)
                     for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))])


@pytest.mark.parametrize("name", ["pinhole", "thinlens"])
def test_primary_ray_directions(name):
    """generate_rays through uniform film points from a fixed lens point: pdf_direction (1 / (A cos^3)), on
    a cap about the optical axis, the frustum (the film rectangle seen from the lens point) as support."""
    camera = PINHOLE if name == "pinhole" else THIN_LENS
    lens_u = np.array([[0.3], [0.8]])
    lens_point = camera.generate_rays(np.array([0]), np.full((2, 1), 0.5), lens_u)[0][:, 0].astype(np.float64)

    def sample(u):
        count = u.shape[1]
        pixels = np.minimum((u[0] * camera.pixel_count).astype(np.int64), camera.pixel_count - 1)
        return camera.generate_rays(pixels, u[1:3], np.repeat(lens_u, count, axis=1))[1]

    def pdf(w):
        return camera.pdf_direction(w, repeat(lens_point, w.shape[1]))

    support = Support.polygon_seen_from(lens_point, film_corners(camera, lens_point))
    result = chi2_test(SphereDomain(camera.forward, np.radians(50.0)), sample, pdf, support=support, dims=3,
                       sample_count=400_000, seed=41, test_count=2)
    check(result)
    assert abs(result.pdf_integral - 1) < 1e-9


@pytest.mark.parametrize("name", ["pinhole", "thinlens"])
def test_film_positions(name):
    """Pixel choice and jitter: the raster position a primary ray projects back to is uniform on the film
    (box pixel filter: density 1 / (width height))."""
    camera = PINHOLE if name == "pinhole" else THIN_LENS

    def sample(u):
        pixels = np.minimum((u[0] * camera.pixel_count).astype(np.int64), camera.pixel_count - 1)
        origins, d = camera.generate_rays(pixels, u[1:3], u[3:5])
        origins = origins.astype(np.float64)
        return camera.raster(origins + 2.0 * d.astype(np.float64), origins)[0]

    domain = PlaneDomain((0.0, camera.width), (0.0, camera.height))
    result = chi2_test(domain, sample, lambda p: np.full(p.shape[1], 1.0 / (camera.width * camera.height)),
                       dims=5, sample_count=300_000, seed=42, test_count=2)
    check(result)


# -- spectral rendering: hero wavelengths -------------------------------------------------------------------


@pytest.mark.parametrize("index", [0, 2], ids=["hero", "rotated"])
@pytest.mark.parametrize("method", WAVELENGTH_SAMPLING)
def test_wavelength_sampling(method, index):
    """sample_wavelengths: the hero wavelength and a rotated one have density wavelength_pdf (per nm); the
    second coordinate is an independent uniform, so the plane harness tests the 1-D density."""
    def sample(u):
        return np.stack((sample_wavelengths(u[0], method)[0][index], u[1]))

    domain = PlaneDomain((LAMBDA_MIN, LAMBDA_MAX), (0.0, 1.0))
    result = chi2_test(domain, sample, lambda p: wavelength_pdf(p[0], method), res=(200, 2), sample_count=200_000,
                       seed=71 + index, test_count=2 * len(WAVELENGTH_SAMPLING))
    check(result)
    assert abs(result.pdf_integral - 1) < 1e-9


# -- control samplers: exact inverse CDFs of densities with closed-form cell integrals ---------------------


def power_sampler(u):
    """x with density 3 x^2 and y with density 2 y on the unit square, by inverse CDFs."""
    return np.stack((np.cbrt(u[0]), np.sqrt(u[1])))


def power_pdf(p):
    inside = (p[0] >= 0) & (p[0] <= 1) & (p[1] >= 0) & (p[1] <= 1)
    return np.where(inside, 6.0 * p[0] ** 2 * p[1], 0.0)


def power_integral(x0, x1, y0, y1):
    return (x1 ** 3 - x0 ** 3) * (y1 ** 2 - y0 ** 2)


def von_mises_fisher(kappa: float):
    """Sampler, density and exact cell integrals (in (cos theta, phi) about z) of the von Mises-Fisher
    distribution p = kappa exp(kappa (cos theta - 1)) / (2 pi (1 - exp(-2 kappa))), by its inverse CDF."""
    norm = kappa / (2 * np.pi * -np.expm1(-2 * kappa))

    def sample(u):
        z = 1.0 + np.log(u[0] + (1 - u[0]) * np.exp(-2 * kappa)) / kappa
        r = np.sqrt(np.maximum(0.0, 1 - z * z))
        phi = 2 * np.pi * u[1]
        return np.stack((r * np.cos(phi), r * np.sin(phi), z))

    def pdf(w):
        return norm * np.exp(kappa * (w[2] - 1))

    def integral(z0, z1, phi0, phi1):
        return norm / kappa * (np.exp(kappa * (z1 - 1)) - np.exp(kappa * (z0 - 1))) * (phi1 - phi0)

    return sample, pdf, integral


CONTROLS = ("plane-quadrature", "plane-exact", "vmf-10-sphere", "vmf-1000-zoomed", "vmf-1000-zoomed-exact")


@pytest.mark.parametrize("name", CONTROLS)
def test_exact_control_samplers_pass(name):
    count = len(CONTROLS)
    if name.startswith("plane"):
        exact = power_integral if name == "plane-exact" else None
        result = chi2_test(PlaneDomain.unit_square(), power_sampler, power_pdf, integral=exact,
                           sample_count=500_000, seed=51, test_count=count)
    else:
        kappa = 10.0 if "10-" in name else 1000.0
        sample, pdf, integral = von_mises_fisher(kappa)
        domain = SphereDomain() if "sphere" in name else SphereDomain((0, 0, 1), 0.15)
        result = chi2_test(domain, sample, pdf, integral=integral if "exact" in name else None,
                           sample_count=500_000, seed=52, test_count=count)
        beyond = 0.0 if "sphere" in name else np.exp(-kappa * (1 - np.cos(0.15)))  # 1.3e-5 beyond the cap
        assert abs(result.pdf_integral - (1 - beyond)) < 1e-9
    check(result)


def test_control_quadrature_matches_exact_integrals():
    """The harness's quadrature of the control densities agrees with their exact cell integrals."""
    sample, pdf, integral = von_mises_fisher(1000.0)
    quadrature = chi2_test(SphereDomain((0, 0, 1), 0.15), sample, pdf, sample_count=100_000)
    exact = chi2_test(SphereDomain((0, 0, 1), 0.15), sample, pdf, integral=integral, sample_count=100_000)
    np.testing.assert_allclose(quadrature.expected, exact.expected, rtol=1e-6, atol=1e-6)


# -- planted bugs fail ------------------------------------------------------------------------------------


def test_pdf_5_percent_high_fails():
    """A density 5% too high: over the whole sphere it integrates to 1.05 ..."""
    result = chi2_test(SphereDomain(), warp.square_to_uniform_sphere,
                       lambda w: 1.05 * warp.square_to_uniform_sphere_pdf(w), sample_count=200_000)
    check(result, passed=False)
    assert "integrates to 1.05" in result.message


def test_pdf_5_percent_high_on_a_zoomed_cap_fails():
    """... and on a zoomed cap, where the density integrates to less than one (the rest of the mass lies
    beyond), the chi-square statistic itself must catch it (the 'beyond' category expects too little)."""
    material, _ = NARROW["phong-e1000"]
    wo = WO["45"]
    sample, pdf = bsdf_routines(BSDFCheck(material, wo))  # cos^1001(0.06) = 16% of the lobe lies beyond 0.06 rad
    result = chi2_test(zoom(mirror(wo), 0.06, offset=0.01), sample, lambda w: 1.05 * pdf(w),
                       support=Support.hemisphere((0, 0, 1)), dims=3, sample_count=500_000, seed=61)
    check(result, passed=False)
    assert result.pdf_integral < 1 and result.p_value < 1e-10


@pytest.mark.parametrize("factor", [0.95, 1.05])
def test_phong_exponent_5_percent_off_fails(factor):
    """Sampling Phong 1000 while the density is Phong 950 or 1050: caught on the zoomed cap."""
    wo = WO["45"]
    sample, _ = bsdf_routines(BSDFCheck(Phong((0.0, 0.0, 0.0), (0.9, 0.9, 0.9), 1000.0), wo))
    _, pdf = bsdf_routines(BSDFCheck(Phong((0.0, 0.0, 0.0), (0.9, 0.9, 0.9), 1000.0 * factor), wo))
    result = chi2_test(zoom(mirror(wo), 0.2), sample, pdf, support=Support.hemisphere((0, 0, 1)), dims=3,
                       sample_count=500_000, seed=62)
    check(result, passed=False)
    assert result.p_value < 1e-10


@pytest.mark.parametrize("factor", [0.95, 1.05])
def test_ggx_roughness_5_percent_off_fails(factor):
    wo = WO["45"]
    sample, _ = bsdf_routines(BSDFCheck(Conductor(alpha=0.01, **GOLD), wo))
    _, pdf = bsdf_routines(BSDFCheck(Conductor(alpha=0.01 * factor, **GOLD), wo))
    result = chi2_test(zoom(mirror(wo), 0.15), sample, pdf, support=Support.hemisphere((0, 0, 1)), dims=3,
                       sample_count=500_000, seed=63)
    check(result, passed=False)
    assert result.p_value < 1e-10


def test_vmf_kappa_5_percent_off_fails():
    sample, _, _ = von_mises_fisher(1000.0)
    _, pdf, integral = von_mises_fisher(1050.0)
    check(chi2_test(SphereDomain((0, 0, 1), 0.15), sample, pdf, integral=integral, sample_count=500_000),
          passed=False)


def test_samples_outside_the_support_fail():
    """A cosine sampler that sends 1 sample in 10^4 below the horizon: outside the support, however few."""
    n = np.array([0.0, 0.0, 1.0])

    def sample(u):
        w = warp.square_to_cosine_about(repeat(n.astype(np.float32), u.shape[1]), u).astype(np.float64)
        flip = u[0] < 1e-4
        w[2, flip] = -np.abs(w[2, flip]) - 0.05
        return w / np.linalg.norm(w, axis=0)

    result = chi2_test(SphereDomain(), sample, lambda w: np.maximum(w[2], 0.0) / np.pi,
                       support=Support.hemisphere(n), sample_count=500_000, seed=64)
    check(result, passed=False)
    assert 0 < result.outside < 100 and "outside the support" in result.message


def test_spot_cone_5_percent_wider_than_its_density_fails():
    """Directions sampled in a 31.5 degree cone against the density of a 30 degree cone: samples beyond the
    cone's edge are outside the support (and the density is too high inside)."""
    sample, pdf, spot = spot_routines(31.5, pdf_cone=30.0)
    result = chi2_test(SphereDomain(spot.axis, np.radians(36.0)), sample, pdf,
                       support=Support.cone(spot.axis, np.radians(30.0)), dims=4, sample_count=300_000)
    check(result, passed=False)
    assert result.outside > 1000


def test_planted_bugs_fail_at_the_family_significance():
    """The planted bugs fail even at the strictest per-test level the families above use."""
    strictest = sidak_significance(ALPHA, len(TRIANGLES) * len(MEASURES))
    sample, _ = bsdf_routines(BSDFCheck(Phong((0.0, 0.0, 0.0), (0.9, 0.9, 0.9), 1000.0), WO["grazing-85"]))
    _, pdf = bsdf_routines(BSDFCheck(Phong((0.0, 0.0, 0.0), (0.9, 0.9, 0.9), 1050.0), WO["grazing-85"]))
    result = chi2_test(zoom(mirror(WO["grazing-85"]), 0.2), sample, pdf,
                       support=Support.hemisphere((0, 0, 1)), dims=3, sample_count=500_000, seed=65,
                       alpha=strictest)
    check(result, passed=False)
