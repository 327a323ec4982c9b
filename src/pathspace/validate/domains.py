"""Domains over which a sampler is chi-square tested, and supports known exactly.

A *domain* is a rectangle of two coordinates (u, v) in which a sampler's
points are histogrammed, with a measure in which the density is given:

:class:`SphereDomain`
    directions on the unit sphere, u = cos theta and v = phi about an
    ``axis`` (du dv is solid angle, so equal (u, v) cells have equal solid
    angle); with ``max_angle`` < pi it is the spherical cap of that angular
    radius about the axis -- a *zoomed* domain whose cells are fine where a
    narrow lobe puts its mass (samples beyond the cap are counted apart).
:class:`PlaneDomain`
    points (x, y) of a rectangle, in area measure: the unit square, a
    triangle's barycentric domain, a lens disk, the film.

A *support* (:class:`Support`) is the set where a density is nonzero when it
is known exactly: an intersection of constraints, each the region where a
simple function is >= 0 -- on the sphere a cap ``a . w >= c`` (hemispheres,
cones, the great circles bounding the spherical polygon a planar polygon
subtends) or a quadric cone ``w^T M w >= 0`` (the directions in which a
disk is seen); in the plane a half-plane or a disk.  Along every line of
constant u a constraint's boundary crosses at points known in closed form
(:meth:`Support.line_roots`; the quadric's as the roots of a quartic in
exp(i phi), polished by Newton's method), along every line of constant v as
well (:meth:`Support.edge_crossings`), and the u where lines of constant u
touch the boundary or pass a corner are known (:meth:`Support.breaks`), so
the chi-square harness integrates a density over exactly the part of each
cell inside the support, and splits the cell where the boundary enters it
instead of hoping a quadrature node lands in a sliver.  Mitsuba 3's
``chi2.py`` (SphericalDomain, PlanarDomain) is the model in spirit; its
domains take no support.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..vecmath import orthonormal_basis

__all__ = ["PlaneDomain", "SphereDomain", "Support"]

TWO_PI = 2.0 * np.pi


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64).reshape(-1)
    length = np.linalg.norm(v)
    if not length > 0:
        raise ValueError(f"expected a nonzero vector, got {v.tolist()}")
    return v / length


_COMPASS = ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1))


def _wrap(phi: np.ndarray) -> np.ndarray:
    """Angles in [-pi, pi)."""
    return np.mod(phi + np.pi, TWO_PI) - np.pi


class SphereDomain:
    """The sphere of directions (or a cap of it) in coordinates u = cos theta, v = phi about ``axis``.

    ``max_angle`` (radians, default pi: the whole sphere) zooms onto the cap
    of directions within that angle of the axis; u then runs from
    cos(max_angle) to 1.  Points are unit vectors (3, N).
    """

    kind = "sphere"
    point_dims = 3

    def __init__(self, axis=(0.0, 0.0, 1.0), max_angle: float = np.pi) -> None:
        if not 0 < max_angle <= np.pi:
            raise ValueError(f"max_angle: expected an angle in (0, pi], got {max_angle!r}")
        self.axis = _unit(axis)
        s, t = orthonormal_basis(self.axis[:, None])
        self.s, self.t = s[:, 0], t[:, 0]
        self.max_angle = float(max_angle)
        self.u_range = (-1.0 if max_angle >= np.pi else float(np.cos(max_angle)), 1.0)
        self.v_range = (-np.pi, np.pi)

    def __repr__(self) -> str:
        if self.max_angle >= np.pi:
            return f"SphereDomain(axis={np.round(self.axis, 6).tolist()})"
        return f"SphereDomain(axis={np.round(self.axis, 6).tolist()}, max_angle={self.max_angle:.6g})"

    @property
    def measure(self) -> float:
        """Solid angle of the domain."""
        return (self.u_range[1] - self.u_range[0]) * TWO_PI

    def default_res(self, cells: int) -> tuple[int, int]:
        """(res_u, res_v) for about ``cells`` cells: twice as many in phi as in cos theta."""
        res_u = max(4, int(np.sqrt(cells / 2)))
        return res_u, 2 * res_u

    def local(self, a) -> np.ndarray:
        """A world vector (3,) in the domain's frame (s, t, axis)."""
        a = np.asarray(a, dtype=np.float64)
        return np.array([a @ self.s, a @ self.t, a @ self.axis])

    def local_matrix(self, m) -> np.ndarray:
        """A world quadratic form (3, 3) in the domain's frame."""
        frame = np.stack((self.s, self.t, self.axis), axis=1)
        return frame.T @ np.asarray(m, dtype=np.float64) @ frame

    def to_uv(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u, v) of directions (3, N)."""
        w = np.asarray(w, dtype=np.float64)
        z = np.clip(self.axis @ w, -1.0, 1.0)
        return z, np.arctan2(self.t @ w, self.s @ w)

    def from_uv(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Unit directions (3, N) of coordinates (u, v)."""
        u = np.asarray(u, dtype=np.float64)
        r = np.sqrt(np.maximum(0.0, 1.0 - u * u))
        return (self.s[:, None] * (r * np.cos(v)) + self.t[:, None] * (r * np.sin(v)) + self.axis[:, None] * u)

    def neighbours(self, w: np.ndarray, distance: float) -> list[np.ndarray]:
        """The directions ``distance`` radians from unit directions w (3, N) toward 8 compass points."""
        w = np.asarray(w, dtype=np.float64)
        s, t = orthonormal_basis(w)
        c, sn = np.cos(distance), np.sin(distance)
        return [c * w + sn * (a * s + b * t) / np.hypot(a, b) for a, b in _COMPASS]


class PlaneDomain:
    """The rectangle ``x`` = (x0, x1) by ``y`` = (y0, y1) of the plane, in area measure; points are (2, N)."""

    kind = "plane"
    point_dims = 2

    def __init__(self, x=(0.0, 1.0), y=(0.0, 1.0)) -> None:
        x0, x1 = map(float, x)
        y0, y1 = map(float, y)
        if not (x1 > x0 and y1 > y0 and np.isfinite([x0, x1, y0, y1]).all()):
            raise ValueError(f"expected finite ranges x0 < x1 and y0 < y1, got {x}, {y}")
        self.u_range, self.v_range = (x0, x1), (y0, y1)

    def __repr__(self) -> str:
        return f"PlaneDomain(x={self.u_range}, y={self.v_range})"

    @classmethod
    def unit_square(cls) -> "PlaneDomain":
        """[0, 1] x [0, 1] (a triangle's barycentric domain is the part with b1 + b2 <= 1: ``Support.triangle()``)."""
        return cls((0.0, 1.0), (0.0, 1.0))

    @classmethod
    def around_disk(cls, radius: float, center=(0.0, 0.0)) -> "PlaneDomain":
        """The square holding the disk of ``radius`` about ``center`` (with ``Support.disk``: a lens)."""
        cx, cy = map(float, center)
        return cls((cx - radius, cx + radius), (cy - radius, cy + radius))

    @property
    def measure(self) -> float:
        """Area of the rectangle."""
        return (self.u_range[1] - self.u_range[0]) * (self.v_range[1] - self.v_range[0])

    def default_res(self, cells: int) -> tuple[int, int]:
        """(res_x, res_y) for about ``cells`` square-ish cells."""
        aspect = (self.u_range[1] - self.u_range[0]) / (self.v_range[1] - self.v_range[0])
        res_y = max(2, int(round(np.sqrt(cells / aspect))))
        return max(2, int(round(res_y * aspect))), res_y

    def to_uv(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u, v) = (x, y) of points (2, N)."""
        p = np.asarray(p, dtype=np.float64)
        return p[0], p[1]

    def from_uv(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Points (2, N) of coordinates (u, v)."""
        return np.stack(np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64)))

    def neighbours(self, p: np.ndarray, distance: float) -> list[np.ndarray]:
        """The points ``distance`` times the rectangle's larger side from points p (2, N) toward 8 compass
        points."""
        p = np.asarray(p, dtype=np.float64)
        step = distance * max(self.u_range[1] - self.u_range[0], self.v_range[1] - self.v_range[0])
        return [p + step * np.array([[a], [b]]) / np.hypot(a, b) for a, b in _COMPASS]


# -- constraints -------------------------------------------------------------------------------------
# Each is the region where value(x) >= 0, and knows where its boundary crosses the lines u = const
# (line_roots: v values) and v = const (edge_crossings: u values) of a domain, and the u values at
# which lines of constant u become tangent to it (breaks: every local extremum of u on the boundary).
# NaN pads missing roots; spurious roots are harmless (the harness keeps a segment if its midpoint is
# inside), missing ones are not.


class _SphereCap:
    """a . w >= c for unit directions w (|a| = 1): a cap, a hemisphere (c = 0), a cone."""

    kind = "sphere"

    def __init__(self, a, c: float) -> None:
        a = np.asarray(a, dtype=np.float64)
        length = np.linalg.norm(a)
        self.a, self.c = a / length, float(c) / length

    def value(self, w: np.ndarray) -> np.ndarray:
        return self.a @ np.asarray(w, dtype=np.float64) - self.c

    def line_roots(self, domain: SphereDomain, u: np.ndarray) -> np.ndarray:
        ax, ay, az = domain.local(self.a)
        r = np.sqrt(np.maximum(0.0, 1.0 - u * u))
        big_r = r * np.hypot(ax, ay)
        with np.errstate(divide="ignore", invalid="ignore"):
            q = (self.c - az * u) / big_r
        ok = (big_r > 0) & (np.abs(q) <= 1.0)
        half = np.arccos(np.clip(q, -1.0, 1.0))
        phi0 = np.arctan2(ay, ax)
        roots = np.stack((_wrap(phi0 - half), _wrap(phi0 + half)), axis=-1)
        return np.where(ok[:, None], roots, np.nan)

    def edge_crossings(self, domain: SphereDomain, v: np.ndarray) -> np.ndarray:
        ax, ay, az = domain.local(self.a)
        e = ax * np.cos(v) + ay * np.sin(v)          # along the meridian: e sin(theta) + az cos(theta) = c
        rho = np.hypot(e, az)
        with np.errstate(divide="ignore", invalid="ignore"):
            q = self.c / rho
        ok = (rho > 0) & (np.abs(q) <= 1.0)
        theta0 = np.arctan2(e, az)
        half = np.arccos(np.clip(q, -1.0, 1.0))
        theta = _wrap(np.stack((theta0 - half, theta0 + half), axis=-1))
        inside = ok[:, None] & (theta >= 0)
        return np.where(inside, np.cos(theta), np.nan)

    def breaks(self, domain: SphereDomain) -> np.ndarray:
        if abs(self.c) >= 1.0:
            return np.zeros(0)
        a = domain.local(self.a)
        theta_a = np.arctan2(np.hypot(a[0], a[1]), a[2])  # accurate near the axis, unlike arccos
        rho = np.arccos(self.c)
        return np.array([np.cos(abs(theta_a - rho)), np.cos(min(theta_a + rho, TWO_PI - theta_a - rho))])


class _SphereQuadric:
    """w^T M w >= 0 for unit directions w (with a cap selecting one nappe: the directions toward a disk)."""

    kind = "sphere"

    def __init__(self, m, rim: Callable[[np.ndarray], np.ndarray] | None = None) -> None:
        m = np.asarray(m, dtype=np.float64)
        self.m = 0.5 * (m + m.T)
        self.rim = rim  # angle (K,) -> unit directions (3, K) along the boundary curve, for the breaks

    def value(self, w: np.ndarray) -> np.ndarray:
        w = np.asarray(w, dtype=np.float64)
        return np.einsum("in,ij,jn->n", w, self.m, w)

    def line_roots(self, domain: SphereDomain, u: np.ndarray) -> np.ndarray:
        m = domain.local_matrix(self.m)
        r2 = np.maximum(0.0, 1.0 - u * u)
        r = np.sqrt(r2)
        # g(phi) = A + B cos phi + C sin phi + D cos 2phi + E sin 2phi along the line; with z = exp(i phi),
        # z^2 g = c4 z^4 + c3 z^3 + c2 z^2 + c1 z + c0 and its roots on the unit circle are the crossings.
        a0 = 0.5 * r2 * (m[0, 0] + m[1, 1]) + m[2, 2] * u * u
        b, c = 2 * r * u * m[0, 2], 2 * r * u * m[1, 2]
        d, e = 0.5 * r2 * (m[0, 0] - m[1, 1]), r2 * m[0, 1]
        coefficients = np.stack(((d - 1j * e) / 2, (b - 1j * c) / 2, a0 + 0j, (b + 1j * c) / 2, (d + 1j * e) / 2),
                                axis=-1)
        z = np.full((u.size, 4), np.nan + 0j)
        scale = np.max(np.abs(coefficients), axis=1)
        quartic = np.abs(coefficients[:, 0]) > 1e-12 * scale
        if quartic.any():
            cq = coefficients[quartic]
            companion = np.zeros((cq.shape[0], 4, 4), dtype=complex)
            companion[:, 0, :] = -cq[:, 1:] / cq[:, :1]
            companion[:, 1, 0] = companion[:, 2, 1] = companion[:, 3, 2] = 1.0
            z[quartic] = np.linalg.eigvals(companion)
        quadratic = ~quartic & (np.abs(coefficients[:, 1]) > 1e-12 * scale)
        if quadratic.any():
            c2, c1, c0 = coefficients[quadratic, 1], coefficients[quadratic, 2], coefficients[quadratic, 3]
            sq = np.sqrt(c1 * c1 - 4 * c2 * c0)
            z[quadratic, :2] = np.stack(((-c1 + sq) / (2 * c2), (-c1 - sq) / (2 * c2)), axis=-1)
        # Candidates near the unit circle (the companion matrix is ill-conditioned when c4 is small), polished
        # by Newton's method on the real g and kept where g vanishes: real crossings, to rounding.
        phi = np.where(np.abs(np.abs(z) - 1.0) < 1e-3, np.angle(z), np.nan)
        coefficient = [x[:, None] for x in (a0, b, c, d, e)]

        def g(x):
            return (coefficient[0] + coefficient[1] * np.cos(x) + coefficient[2] * np.sin(x)
                    + coefficient[3] * np.cos(2 * x) + coefficient[4] * np.sin(2 * x))

        def slope(x):
            return (-coefficient[1] * np.sin(x) + coefficient[2] * np.cos(x) - 2 * coefficient[3] * np.sin(2 * x)
                    + 2 * coefficient[4] * np.cos(2 * x))

        with np.errstate(divide="ignore", invalid="ignore"):
            for _ in range(3):
                step = g(phi) / slope(phi)
                better = np.isfinite(step) & (np.abs(g(phi - step)) <= np.abs(g(phi)))
                phi = np.where(better, phi - step, phi)
            return np.where(np.abs(g(phi)) <= 1e-9 * scale[:, None], _wrap(phi), np.nan)

    def edge_crossings(self, domain: SphereDomain, v: np.ndarray) -> np.ndarray:
        m = domain.local_matrix(self.m)
        cv, sv = np.cos(v), np.sin(v)
        h = m[0, 0] * cv * cv + 2 * m[0, 1] * cv * sv + m[1, 1] * sv * sv
        k = m[0, 2] * cv + m[1, 2] * sv
        # Along the meridian w = sin(theta) e_h + cos(theta) e_z: g = p + q cos(2 theta) + k sin(2 theta).
        p, q = 0.5 * (h + m[2, 2]), 0.5 * (m[2, 2] - h)
        rho = np.hypot(q, k)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = -p / rho
        ok = (rho > 0) & (np.abs(ratio) <= 1.0)
        psi0 = np.arctan2(k, q)
        half = np.arccos(np.clip(ratio, -1.0, 1.0))
        theta = 0.5 * np.mod(np.stack((psi0 - half, psi0 + half), axis=-1), TWO_PI)
        return np.where(ok[:, None], np.cos(theta), np.nan)

    def breaks(self, domain: SphereDomain) -> np.ndarray:
        """The u of every local extremum of u along the rim (two for a cone about the domain's axis, four
        when the axis is inside an elongated one): sampled, then refined by a bounded 1-D search (u is
        flat there, so the search's angle tolerance leaves u exact to rounding)."""
        if self.rim is None:
            return np.zeros(0)
        count = 1024
        angle = np.linspace(0.0, TWO_PI, count, endpoint=False)
        from scipy import optimize  # here, not at module level: keeps `import pathspace` light

        u = domain.to_uv(self.rim(angle))[0]
        step = TWO_PI / count
        before, after = np.roll(u, 1), np.roll(u, -1)
        out = []
        # Strict local extrema (one of a plateau), and the global ones (a rim of constant u has no other).
        for sign, extremes, best in ((-1.0, (u > before) & (u >= after), np.argmax(u)),
                                     (1.0, (u < before) & (u <= after), np.argmin(u))):
            for k in np.union1d(np.flatnonzero(extremes), [best]):
                best = optimize.minimize_scalar(lambda x: sign * domain.to_uv(self.rim(np.array([x])))[0][0],
                                                bounds=(angle[k] - step, angle[k] + step), method="bounded",
                                                options={"xatol": 1e-12})
                out.append(sign * min(best.fun, sign * u[k]))
        return np.array(out)


class _HalfPlane:
    """a . p >= c for points p (2,)."""

    kind = "plane"

    def __init__(self, a, c: float) -> None:
        self.a, self.c = np.asarray(a, dtype=np.float64), float(c)

    def value(self, p: np.ndarray) -> np.ndarray:
        return self.a @ np.asarray(p, dtype=np.float64) - self.c

    def line_roots(self, domain, u: np.ndarray) -> np.ndarray:
        ax, ay = self.a
        if ay == 0:
            return np.full((u.size, 1), np.nan)
        return ((self.c - ax * u) / ay)[:, None]

    def edge_crossings(self, domain, v: np.ndarray) -> np.ndarray:
        ax, ay = self.a
        if ax == 0:
            return np.full((v.size, 1), np.nan)
        return ((self.c - ay * v) / ax)[:, None]

    def breaks(self, domain) -> np.ndarray:
        ax, ay = self.a
        return np.array([self.c / ax]) if ay == 0 else np.zeros(0)


class _Disk:
    """|p - center| <= radius for points p (2,)."""

    kind = "plane"

    def __init__(self, center, radius: float) -> None:
        self.center, self.radius = np.asarray(center, dtype=np.float64), float(radius)

    def value(self, p: np.ndarray) -> np.ndarray:
        d = np.asarray(p, dtype=np.float64) - self.center[:, None]
        return self.radius ** 2 - (d[0] ** 2 + d[1] ** 2)

    def _chord(self, offset: np.ndarray, middle: float) -> np.ndarray:
        h2 = self.radius ** 2 - offset * offset
        h = np.sqrt(np.maximum(h2, 0.0))
        return np.where((h2 >= 0)[:, None], np.stack((middle - h, middle + h), axis=-1), np.nan)

    def line_roots(self, domain, u: np.ndarray) -> np.ndarray:
        return self._chord(u - self.center[0], self.center[1])

    def edge_crossings(self, domain, v: np.ndarray) -> np.ndarray:
        return self._chord(v - self.center[1], self.center[0])

    def breaks(self, domain) -> np.ndarray:
        return np.array([self.center[0] - self.radius, self.center[0] + self.radius])


class Support:
    """Where a density is nonzero, known exactly: the intersection of constraints (see the module docstring).

    Build one with the constructors (``hemisphere``, ``cone``, ``polygon_seen_from``, ``disk_seen_from``
    on the sphere; ``half_plane``, ``polygon``, ``triangle``, ``disk`` in the plane) and intersect with
    ``&``.  ``contains(points)`` is the indicator; the chi-square harness also uses the boundary
    crossings to integrate each cell over the support only.  ``corners`` are points where two
    boundaries meet (a polygon's vertices): lines through them are where the shape of the support
    along a line changes, so cells are split there.
    """

    def __init__(self, constraints: list, corners: np.ndarray | None = None, name: str = "support") -> None:
        kinds = {c.kind for c in constraints}
        if len(kinds) != 1:
            raise ValueError("a support needs constraints of one kind (sphere or plane)")
        self.kind = kinds.pop()
        self.constraints = list(constraints)
        dims = 3 if self.kind == "sphere" else 2
        self.corners = np.zeros((dims, 0)) if corners is None else np.asarray(corners, dtype=np.float64).reshape(dims, -1)
        self.name = name

    def __repr__(self) -> str:
        return f"Support({self.name})"

    def __and__(self, other: "Support") -> "Support":
        if other.kind != self.kind:
            raise ValueError("a support needs constraints of one kind (sphere or plane)")
        return Support(self.constraints + other.constraints, np.concatenate((self.corners, other.corners), axis=1),
                       f"{self.name} & {other.name}")

    def check_domain(self, domain: SphereDomain | PlaneDomain) -> None:
        """Raise ValueError unless ``domain`` is of the support's kind (sphere or plane)."""
        if domain.kind != self.kind:
            raise ValueError(f"a {self.kind} support cannot be used on a {domain.kind} domain")

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Whether points ((3, N) directions or (2, N) points) are in the support (boundary included)."""
        inside = np.ones(np.asarray(points).shape[1], dtype=bool)
        for constraint in self.constraints:
            inside &= constraint.value(points) >= 0
        return inside

    def line_roots(self, domain, u: np.ndarray) -> np.ndarray:
        """(K, m) v values where the boundary crosses the lines u = u[k] (NaN padded)."""
        return np.concatenate([c.line_roots(domain, u) for c in self.constraints], axis=1)

    def edge_crossings(self, domain, v: np.ndarray) -> np.ndarray:
        """(K, m) u values where the boundary crosses the lines v = v[k] (NaN padded)."""
        return np.concatenate([c.edge_crossings(domain, v) for c in self.constraints], axis=1)

    def breaks(self, domain) -> np.ndarray:
        """u values where lines of constant u touch the boundary or pass a corner."""
        parts = [c.breaks(domain) for c in self.constraints]
        if self.corners.shape[1]:
            parts.append(domain.to_uv(self.corners)[0])
        values = np.concatenate(parts) if parts else np.zeros(0)
        return np.unique(values[np.isfinite(values)])

    # -- sphere --------------------------------------------------------------------------------

    @classmethod
    def cap(cls, axis, cos_angle: float) -> "Support":
        """Directions w with axis . w >= cos_angle: a cone (a spot light's) or, with 0, a hemisphere."""
        return cls([_SphereCap(_unit(axis), cos_angle)], name=f"cap(cos={cos_angle:.6g})")

    @classmethod
    def cone(cls, axis, angle: float) -> "Support":
        """Directions within ``angle`` radians of ``axis``."""
        return cls.cap(axis, float(np.cos(angle)))

    @classmethod
    def hemisphere(cls, normal) -> "Support":
        """Directions on the side of ``normal``."""
        return cls([_SphereCap(_unit(normal), 0.0)], name="hemisphere")

    @classmethod
    def polygon_seen_from(cls, apex, vertices) -> "Support":
        """The directions from ``apex`` (3,) through a convex planar polygon ``vertices`` (K, 3): for a
        triangle, the spherical triangle it subtends (a triangle light seen from a receiver); for a
        rectangle, a camera's frustum."""
        apex = np.asarray(apex, dtype=np.float64)
        d = np.asarray(vertices, dtype=np.float64) - apex[None, :]
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        centre = _unit(d.mean(axis=0))
        constraints = []
        for k in range(len(d)):
            n = np.cross(d[k], d[(k + 1) % len(d)])
            n = n if n @ centre >= 0 else -n
            constraints.append(_SphereCap(n, 0.0))
        return cls(constraints, d.T, name=f"spherical polygon of {len(d)} vertices")

    @classmethod
    def disk_seen_from(cls, apex, center, normal, radius: float) -> "Support":
        """The directions from ``apex`` toward the disk of ``radius`` about ``center`` with ``normal`` (a
        thin lens seen from a scene point): an oblique circular cone, a quadric."""
        apex, center = np.asarray(apex, dtype=np.float64), np.asarray(center, dtype=np.float64)
        n = _unit(normal)
        q = center - apex
        dist = n @ q
        if dist == 0:
            raise ValueError("the apex lies in the disk's plane: it sees the disk edge-on")
        # |t w - q| <= radius at t = dist / (n . w), times (n . w)^2 (with |w| = 1):
        m = -(dist * dist * np.eye(3) - dist * (np.outer(n, q) + np.outer(q, n)) + (q @ q - radius ** 2) * np.outer(n, n))
        s, t = orthonormal_basis(n[:, None])

        def rim(angle: np.ndarray) -> np.ndarray:
            d = q[:, None] + radius * (s * np.cos(angle) + t * np.sin(angle))
            return d / np.linalg.norm(d, axis=0)

        return cls([_SphereQuadric(m, rim), _SphereCap(np.sign(dist) * n, 0.0)], name="disk seen from a point")

    # -- plane ---------------------------------------------------------------------------------

    @classmethod
    def half_plane(cls, a, c: float) -> "Support":
        """Points p with a . p >= c."""
        return cls([_HalfPlane(a, c)], name="half-plane")

    @classmethod
    def polygon(cls, vertices) -> "Support":
        """The convex polygon ``vertices`` (K, 2), either orientation."""
        v = np.asarray(vertices, dtype=np.float64)
        centre = v.mean(axis=0)
        constraints = []
        for k in range(len(v)):
            edge = v[(k + 1) % len(v)] - v[k]
            a = np.array([-edge[1], edge[0]])
            a = a if a @ (centre - v[k]) >= 0 else -a
            constraints.append(_HalfPlane(a, a @ v[k]))
        return cls(constraints, v.T, name=f"polygon of {len(v)} vertices")

    @classmethod
    def triangle(cls, vertices=((0.0, 0.0), (1.0, 0.0), (0.0, 1.0))) -> "Support":
        """A triangle; by default the barycentric domain b1, b2 >= 0, b1 + b2 <= 1."""
        return cls.polygon(vertices)

    @classmethod
    def disk(cls, radius: float, center=(0.0, 0.0)) -> "Support":
        """The disk of ``radius`` about ``center``."""
        return cls([_Disk(center, radius)], name="disk")
