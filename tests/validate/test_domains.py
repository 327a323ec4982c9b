"""Domains and supports of the chi-square harness (pathspace.validate.domains) and its quadrature
(pathspace.validate.integrate_bins): coordinates round-trip, measures, boundary crossings lie on the
boundary, and densities integrate exactly -- a uniform density gives every cell its exact share, a constant
density on a cone, a spherical triangle or polygon, a disk seen from a point, a plane disk or a triangle
integrates to 1 within 1e-9 (closed forms: cap areas, Van Oosterom & Strackee's solid angle of a triangle,
the solid angle of a rectangle, of a disk on its axis), and cell by cell against independent references
(polygon clipping in the plane, 1-D adaptive quadrature of a cap's arc length per cell)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from pathspace.validate import PlaneDomain, SphereDomain, Support, integrate_bins

RNG = np.random.default_rng(20)


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def random_directions(count: int, rng=RNG) -> np.ndarray:
    w = rng.normal(size=(3, count))
    return w / np.linalg.norm(w, axis=0)


def constant(value: float):
    return lambda x: np.full(x.shape[1], value)


def van_oosterom_strackee(apex, vertices) -> float:
    """Solid angle of the triangle ``vertices`` (3, 3) seen from ``apex``: tan(Omega / 2) = |a . (b x c)| /
    (abc + (a.b) c + (a.c) b + (b.c) a) for the vectors a, b, c from the apex (Van Oosterom & Strackee 1983)."""
    a, b, c = (np.asarray(v, dtype=np.float64) - np.asarray(apex, dtype=np.float64) for v in vertices)
    la, lb, lc = np.linalg.norm(a), np.linalg.norm(b), np.linalg.norm(c)
    numerator = abs(a @ np.cross(b, c))
    denominator = la * lb * lc + (a @ b) * lc + (a @ c) * lb + (b @ c) * la
    return 2.0 * np.arctan2(numerator, denominator)


# -- domains ----------------------------------------------------------------------------------------------

DOMAINS = {"sphere": SphereDomain(), "sphere-tilted": SphereDomain((0.3, -0.8, 0.2)),
           "cap": SphereDomain((0.0, 0.6, -0.8), 0.4), "cap-down": SphereDomain((0.0, 0.0, -1.0), 2.5)}


@pytest.mark.parametrize("name", DOMAINS)
def test_sphere_coordinates_round_trip(name):
    domain = DOMAINS[name]
    w = random_directions(10_000)
    u, v = domain.to_uv(w)
    np.testing.assert_allclose(domain.from_uv(u, v), w, atol=1e-12)
    assert np.all((v >= -np.pi) & (v <= np.pi))
    uu = RNG.uniform(*domain.u_range, 10_000)
    vv = RNG.uniform(*domain.v_range, 10_000)
    back_u, back_v = domain.to_uv(domain.from_uv(uu, vv))
    np.testing.assert_allclose(back_u, uu, atol=1e-12)
    np.testing.assert_allclose(np.angle(np.exp(1j * (back_v - vv))), 0.0, atol=1e-7)  # phi is exact up to 2 pi
    assert np.allclose(np.linalg.norm(domain.from_uv(uu, vv), axis=0), 1.0)
    # u is cos theta about the axis: the domain's points are the directions within max_angle of the axis
    assert np.all(domain.axis @ domain.from_uv(uu, vv) >= np.cos(domain.max_angle) - 1e-12)


def test_sphere_measure_and_resolution():
    assert SphereDomain().measure == pytest.approx(4 * np.pi, rel=1e-15)
    assert SphereDomain((1, 0, 0), 0.3).measure == pytest.approx(2 * np.pi * (1 - np.cos(0.3)), rel=1e-14)
    assert SphereDomain().default_res(5000) == (50, 100)
    with pytest.raises(ValueError, match="max_angle"):
        SphereDomain((0, 0, 1), 0.0)
    with pytest.raises(ValueError, match="nonzero"):
        SphereDomain((0, 0, 0))


def test_plane_coordinates_measure_and_resolution():
    domain = PlaneDomain((-1.0, 3.0), (0.5, 1.5))
    p = np.stack((RNG.uniform(-1, 3, 100), RNG.uniform(0.5, 1.5, 100)))
    np.testing.assert_array_equal(domain.from_uv(*domain.to_uv(p)), p)
    assert domain.measure == 4.0
    res = domain.default_res(400)
    assert res[0] == 4 * res[1] and abs(res[0] * res[1] - 400) <= 40
    lens = PlaneDomain.around_disk(0.2, (1.0, -1.0))
    assert (lens.u_range, lens.v_range) == ((0.8, 1.2), (-1.2, -0.8))
    assert PlaneDomain.unit_square().measure == 1.0
    with pytest.raises(ValueError):
        PlaneDomain((1.0, 1.0), (0.0, 1.0))


def test_neighbours_are_at_the_edge_tolerance():
    """The points the stray rule looks at: ``distance`` radians away on the sphere, ``distance`` times the
    larger side in the plane, in 8 directions."""
    w = random_directions(100)
    neighbours = SphereDomain((0, 1, 0), 0.5).neighbours(w, 1e-5)
    assert len(neighbours) == 8
    for n in neighbours:
        np.testing.assert_allclose(np.linalg.norm(n, axis=0), 1.0, atol=1e-15)
        np.testing.assert_allclose(np.arccos(np.clip((n * w).sum(axis=0), -1, 1)), 1e-5, rtol=1e-3)
    p = np.zeros((2, 3))
    for n in PlaneDomain((0.0, 2.0), (0.0, 1.0)).neighbours(p, 1e-3):
        np.testing.assert_allclose(np.hypot(*n), 2e-3)


# -- supports: boundaries -------------------------------------------------------------------------------

SPHERE_SUPPORTS = {
    "cone": Support.cone((0.3, 0.2, 0.9), 0.3),
    "narrow-cone": Support.cone((0.3, -1.2, -0.1), np.radians(2.0)),
    "hemisphere": Support.hemisphere((0.2, -0.4, 0.7)),
    "spherical-triangle": Support.polygon_seen_from(np.zeros(3), [[-0.3, 0.2, -1.0], [0.6, 0.1, -0.8],
                                                                  [0.1, 0.9, -1.2]]),
    "disk-seen-obliquely": Support.disk_seen_from((1.0, 0.3, 0.02), (0, 0, 0), (0, 0, 1), 0.2),
}


@pytest.mark.parametrize("name", SPHERE_SUPPORTS)
def test_sphere_crossings_lie_on_the_boundary(name):
    """line_roots (v on lines of constant u) and edge_crossings (u on lines of constant v) are zeros of a
    constraint, and the support changes from inside to outside across them."""
    support = SPHERE_SUPPORTS[name]
    domain = SphereDomain((0.1, 0.3, 0.9))
    u = np.linspace(-0.999, 0.999, 301)
    v = np.linspace(-np.pi, np.pi, 301)
    for along, coordinates, roots in (("u", u, support.line_roots(domain, u)),
                                      ("v", v, support.edge_crossings(domain, v))):
        rows, cols = np.nonzero(np.isfinite(roots))
        assert rows.size >= 4
        for row, col in zip(rows, cols):
            r = roots[row, col]
            uv = (coordinates[row], r) if along == "u" else (r, coordinates[row])
            point = domain.from_uv(np.atleast_1d(uv[0]), np.atleast_1d(uv[1]))
            values = [abs(c.value(point)[0]) for c in support.constraints]
            assert min(values) < 1e-9, (along, coordinates[row], r, values)


def test_breaks_are_where_lines_of_constant_u_touch_the_boundary():
    """A cap's breaks are the extreme u on its boundary; an elongated cone around the domain's axis has
    four (two nearest and two farthest points of its rim)."""
    domain = SphereDomain((0.0, 0.0, 1.0))
    axis = unit((0.5, 0.0, 0.8))
    breaks = Support.cone(axis, 0.2).breaks(domain)
    theta = np.arccos(axis[2])
    np.testing.assert_allclose(np.sort(breaks), [np.cos(theta + 0.2), np.cos(theta - 0.2)], rtol=1e-14)
    # A disk seen edge-on from a point almost in its plane, with the domain's axis toward its centre.
    receiver = np.array([1.0, 0.3, 0.02])
    support = Support.disk_seen_from(receiver, (0, 0, 0), (0, 0, 1), 0.2)
    tilted = SphereDomain(-receiver + 0.01 * np.array([-0.3, 1.0, 0.0]), 0.3)  # off centre along the long axis
    rim = np.array([[0.2 * np.cos(a), 0.2 * np.sin(a), 0.0] for a in np.linspace(0, 2 * np.pi, 200_001)]).T
    rim = rim - receiver[:, None]
    u = tilted.to_uv(rim / np.linalg.norm(rim, axis=0))[0]
    extremes = np.sort(np.unique(np.round(support.constraints[0].breaks(tilted), 12)))
    assert extremes.size == 4
    np.testing.assert_allclose([extremes[0], extremes[-1]], [u.min(), u.max()], atol=1e-10)


def test_support_contains_and_intersection():
    cone = Support.cone((0, 0, 1), 0.5)
    upper = Support.hemisphere((1, 0, 0))
    both = cone & upper
    w = random_directions(20_000)
    np.testing.assert_array_equal(both.contains(w), (w[2] >= np.cos(0.5)) & (w[0] >= 0))
    assert "cap" in repr(both) and "hemisphere" in repr(both)
    triangle = Support.triangle()
    p = RNG.random((2, 10_000))
    np.testing.assert_array_equal(triangle.contains(p), p[0] + p[1] <= 1)
    with pytest.raises(ValueError, match="plane"):
        integrate_bins(SphereDomain(), constant(1.0), (4, 8), support=triangle)
    with pytest.raises(ValueError, match="one kind"):
        cone & triangle
    with pytest.raises(ValueError, match="edge-on"):
        Support.disk_seen_from((1.0, 0.0, 0.0), (0, 0, 0), (0, 0, 1), 0.5)


# -- integrate_bins: exact cells and totals ---------------------------------------------------------------


@pytest.mark.parametrize("name", DOMAINS)
def test_uniform_density_gives_every_cell_its_exact_area(name):
    """(cos theta, phi) cells have equal solid angle: the uniform density 1 / (4 pi) gives each exactly
    measure / (4 pi cells)."""
    domain = DOMAINS[name]
    cells, error, ok = integrate_bins(domain, constant(1 / (4 * np.pi)), (12, 24))
    assert ok and error < 1e-14
    np.testing.assert_allclose(cells, domain.measure / (4 * np.pi) / cells.size, rtol=1e-13)


def test_uniform_density_in_the_plane():
    domain = PlaneDomain((-1.0, 3.0), (0.5, 1.5))
    cells, _, ok = integrate_bins(domain, constant(0.25), (8, 3))
    assert ok
    np.testing.assert_allclose(cells, 1 / 24, rtol=1e-14)


def rectangle_solid_angle(half_width: float, half_height: float, distance: float) -> float:
    """Solid angle of a rectangle seen from a point on its axis: 4 arcsin(a b / sqrt((a^2 + d^2)(b^2 + d^2)))."""
    a, b, d = half_width, half_height, distance
    return 4.0 * np.arcsin(a * b / np.sqrt((a * a + d * d) * (b * b + d * d)))


TRIANGLES = {"ordinary": ([0.0, 0.0, 0.0], [[-0.3, 0.2, -1.0], [0.6, 0.1, -0.8], [0.1, 0.9, -1.2]]),
             "grazing": ([1.5, 1e-3, 1.2], [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
             "sliver": ([0.3, 0.5, 0.2], [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 0.0, 0.01]]),
             "wide": ([0.2, 0.0, 0.1], [[-3.0, 0.5, -3.0], [3.0, 0.5, -3.0], [0.0, 0.5, 4.0]])}


def sphere_cases():
    """name -> (support, its solid angle in closed form, domains to integrate over)."""
    cases = {}
    for angle in (0.3, np.radians(2.0), 2.5):
        for axis_name, axis in (("tilted", unit((0.3, -1.2, -0.1))), ("pole", (0.0, 0.0, 1.0)),
                                ("seam", unit((-1.0, 1e-9, 0.3)))):
            cases[f"cone-{angle:.3f}-{axis_name}"] = (Support.cone(axis, angle), 2 * np.pi * (1 - np.cos(angle)),
                                                     [SphereDomain(), SphereDomain(axis, min(np.pi, 1.2 * angle))])
    cases["hemisphere"] = (Support.hemisphere((0.2, -0.4, 0.7)), 2 * np.pi, [SphereDomain()])
    for name, (apex, vertices) in TRIANGLES.items():
        directions = np.asarray(vertices) - np.asarray(apex)
        centre = unit((directions / np.linalg.norm(directions, axis=1, keepdims=True)).sum(axis=0))
        reach = np.arccos(np.clip(directions @ centre / np.linalg.norm(directions, axis=1), -1, 1)).max()
        cases[f"triangle-{name}"] = (Support.polygon_seen_from(apex, vertices), van_oosterom_strackee(apex, vertices),
                                     [SphereDomain(), SphereDomain(centre, min(np.pi, 1.05 * reach))])
    rectangle = [[-0.6, -0.4, 1.0], [0.6, -0.4, 1.0], [0.6, 0.4, 1.0], [-0.6, 0.4, 1.0]]
    cases["frustum"] = (Support.polygon_seen_from(np.zeros(3), rectangle), rectangle_solid_angle(0.6, 0.4, 1.0),
                        [SphereDomain(), SphereDomain((0, 0, 1), 1.0)])
    d, r = 1.7, 0.4
    cases["disk-on-axis"] = (Support.disk_seen_from((0, 0, d), (0, 0, 0), (0, 0, 1), r),
                             2 * np.pi * (1 - d / np.hypot(d, r)), [SphereDomain(), SphereDomain((0, 0, -1), 0.4)])
    return cases


SPHERE_CASES = sphere_cases()


@pytest.mark.parametrize("name", SPHERE_CASES)
def test_constant_density_on_a_sphere_support_integrates_to_one(name):
    support, solid_angle, domains = SPHERE_CASES[name]
    for domain in domains:
        for res in ((16, 32), (37, 74)):
            cells, error, ok = integrate_bins(domain, constant(1 / solid_angle), res, support=support)
            assert ok
            assert abs(cells.sum() - 1) < 1e-9, (domain, res, cells.sum() - 1, error)
            assert error < 1e-6


@pytest.mark.parametrize("receiver", [(0.3, -0.2, 1.0), (1.0, 0.3, 0.02), (-3.0, 1.0, 0.05), (0.05, 0.0, -0.3)])
def test_density_of_directions_toward_a_disk_integrates_to_one(receiver):
    """Directions toward uniform points of a disk have density d^2 / (|cos| area): it integrates to 1 over
    the disk seen from the receiver, also nearly edge-on and from behind."""
    receiver = np.asarray(receiver, dtype=np.float64)
    radius = 0.2

    def pdf(w):
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -receiver[2] / w[2]
            p = receiver[:, None] + w * t
            on = (t > 0) & (p[0] ** 2 + p[1] ** 2 <= radius ** 2)
            return np.where(on, t * t / (np.abs(w[2]) * np.pi * radius ** 2), 0.0)

    support = Support.disk_seen_from(receiver, (0, 0, 0), (0, 0, 1), radius)
    for domain in (SphereDomain(), SphereDomain(-receiver, 0.8)):
        cells, error, ok = integrate_bins(domain, pdf, (31, 62), support=support)
        assert ok and abs(cells.sum() - 1) < 1e-9, (domain, cells.sum() - 1, error)


def polygon_area(vertices: np.ndarray) -> float:
    x, y = vertices[:, 0], vertices[:, 1]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def clip(polygon: np.ndarray, x0: float, x1: float, y0: float, y1: float) -> np.ndarray:
    """Sutherland-Hodgman clipping of a convex polygon (K, 2) to a rectangle."""
    for axis, bound, keep_above in ((0, x0, True), (0, x1, False), (1, y0, True), (1, y1, False)):
        out = []
        for k in range(len(polygon)):
            p, q = polygon[k], polygon[(k + 1) % len(polygon)]
            p_in = p[axis] >= bound if keep_above else p[axis] <= bound
            q_in = q[axis] >= bound if keep_above else q[axis] <= bound
            if p_in:
                out.append(p)
            if p_in != q_in:
                t = (bound - p[axis]) / (q[axis] - p[axis])
                out.append(p + t * (q - p))
        polygon = np.array(out)
        if len(polygon) == 0:
            return polygon
    return polygon


PLANE_POLYGONS = {"barycentric": [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]],
                  "triangle": [[0.1, 0.05], [0.93, 0.4], [0.3, 0.97]],
                  "sliver": [[0.02, 0.1], [0.98, 0.13], [0.5, 0.1151]],
                  "quad": [[0.2, 0.1], [0.9, 0.3], [0.8, 0.8], [0.1, 0.6]]}


@pytest.mark.parametrize("name", PLANE_POLYGONS)
def test_constant_density_on_a_polygon_matches_clipped_areas(name):
    """Cell by cell, a constant density on a polygon gives the area of the polygon clipped to the cell."""
    vertices = np.asarray(PLANE_POLYGONS[name])
    area = polygon_area(vertices)
    domain = PlaneDomain.unit_square()
    res = (9, 7)
    cells, _, ok = integrate_bins(domain, constant(1 / area), res, support=Support.polygon(vertices))
    assert ok and abs(cells.sum() - 1) < 1e-10
    for i in range(res[0]):
        for j in range(res[1]):
            piece = clip(vertices, i / res[0], (i + 1) / res[0], j / res[1], (j + 1) / res[1])
            exact = polygon_area(piece) / area if len(piece) else 0.0
            assert cells[i, j] == pytest.approx(exact, abs=1e-11), (i, j)


def disk_cell_area(radius: float, x0: float, x1: float, y0: float, y1: float) -> float:
    """Area of the disk about the origin inside a rectangle, by 1-D adaptive quadrature of chord lengths."""
    def chord(x):
        h = np.sqrt(max(radius * radius - x * x, 0.0))
        return max(0.0, min(h, y1) - max(-h, y0))

    a, b = max(x0, -radius), min(x1, radius)
    if b <= a:
        return 0.0
    return quad(chord, a, b, points=[p for p in (-radius, radius) if a < p < b] or None, epsabs=1e-14,
                epsrel=1e-12, limit=200)[0]


def test_constant_density_on_a_disk_matches_cell_areas():
    radius = 0.2
    domain = PlaneDomain.around_disk(radius)
    res = (7, 7)
    cells, _, ok = integrate_bins(domain, constant(1 / (np.pi * radius ** 2)), res, support=Support.disk(radius))
    assert ok and abs(cells.sum() - 1) < 1e-12
    edges = np.linspace(-radius, radius, 8)
    for i in range(7):
        for j in range(7):
            exact = disk_cell_area(radius, edges[i], edges[i + 1], edges[j], edges[j + 1]) / (np.pi * radius ** 2)
            assert cells[i, j] == pytest.approx(exact, abs=1e-11), (i, j)


def test_half_plane_and_linear_density():
    """A linear density on a half-plane of the unit square: exact totals (2 x on x >= 0.3 ...)."""
    support = Support.half_plane((1.0, 0.0), 0.3)  # x >= 0.3, a vertical boundary: a break in u

    def pdf(p):
        return 2 * p[0] / (1 - 0.09)

    cells, _, ok = integrate_bins(PlaneDomain.unit_square(), pdf, (5, 5), support=support)
    assert ok and abs(cells.sum() - 1) < 1e-11
    assert np.all(cells[0] == 0)  # x < 0.2 is outside
    np.testing.assert_allclose(cells[1], (0.4 ** 2 - 0.3 ** 2) / (1 - 0.09) / 5, rtol=1e-12)


@pytest.mark.parametrize("axis_name", ["tilted", "near-pole"])
def test_cone_cells_match_arc_lengths(axis_name):
    """Cell by cell, a cone's solid angle in (cos theta, phi) cells equals the integral over u of the arc
    of the cell's phi range inside the cone (1-D adaptive quadrature, independent of the harness)."""
    axis = unit((0.3, -1.2, -0.1)) if axis_name == "tilted" else unit((0.05, 0.02, 1.0))
    rho = 0.25
    domain = SphereDomain()
    res = (16, 32)
    cells, _, ok = integrate_bins(domain, constant(1.0), res, support=Support.cone(axis, rho))
    assert ok
    ax, ay, az = axis
    phi0 = np.arctan2(ay, ax)
    c = np.cos(rho)

    def arc(u, v0, v1):
        big_r = np.sqrt(1 - u * u) * np.hypot(ax, ay)
        q = (c - az * u) / big_r if big_r > 0 else np.copysign(np.inf, c - az * u)
        if q <= -1:
            return v1 - v0
        if q >= 1:
            return 0.0
        half = np.arccos(q)
        total = 0.0
        for shift in (-2 * np.pi, 0.0, 2 * np.pi):  # the arc [phi0 - half, phi0 + half], wrapped
            total += max(0.0, min(phi0 + half + shift, v1) - max(phi0 - half + shift, v0))
        return total

    def kinks(u0, u1, v0, v1):
        """Where the arc's ends cross the cell's edges v0, v1 (a dense scan, then Brent's method), and
        where lines of constant u touch the cone: the points quad must be told about."""
        points = [np.cos(np.arccos(az) + rho), np.cos(abs(np.arccos(az) - rho))]
        for sign in (-1, 1):
            for edge in (v0, v1):
                def end(u):
                    q = (c - az * u) / max(np.sqrt(1 - u * u) * np.hypot(ax, ay), 1e-300)
                    gap = phi0 + sign * np.arccos(np.clip(q, -1, 1)) - edge
                    return np.angle(np.exp(1j * gap)) if abs(q) < 1 else np.nan
                grid = np.linspace(u0, u1, 2001)
                values = np.array([end(u) for u in grid])
                for k in np.flatnonzero((values[:-1] * values[1:] < 0) & (np.abs(values[:-1] - values[1:]) < 1)):
                    points.append(brentq(end, grid[k], grid[k + 1], xtol=1e-15))
        return sorted(p for p in points if u0 < p < u1)

    for i, j in np.argwhere(cells > 0):
        u0, u1 = -1 + 2 * i / res[0], -1 + 2 * (i + 1) / res[0]
        v0, v1 = -np.pi + 2 * np.pi * j / res[1], -np.pi + 2 * np.pi * (j + 1) / res[1]
        exact = quad(lambda u: arc(u, v0, v1), u0, u1, points=kinks(u0, u1, v0, v1) or None, epsabs=1e-15,
                     epsrel=1e-12, limit=400)[0]
        assert cells[i, j] == pytest.approx(exact, abs=1e-12), (i, j)
    assert cells.sum() == pytest.approx(2 * np.pi * (1 - c), rel=1e-12)


def test_without_a_support_edges_are_refined():
    """Without a support the quadrature still converges at an edge it does not know, only more slowly: a
    cone's indicator integrates to its area within 1e-4 (exact with the support)."""
    axis, rho = unit((0.3, 0.2, 0.9)), 0.3
    cone = Support.cone(axis, rho)
    area = 2 * np.pi * (1 - np.cos(rho))
    pdf = lambda w: np.where(axis @ w >= np.cos(rho), 1 / area, 0.0)  # noqa: E731
    blind, _, _ = integrate_bins(SphereDomain(), pdf, (16, 32))
    exact, _, _ = integrate_bins(SphereDomain(), pdf, (16, 32), support=cone)
    assert abs(blind.sum() - 1) < 1e-4
    assert abs(exact.sum() - 1) < 1e-12
