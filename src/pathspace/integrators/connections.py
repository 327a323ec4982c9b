"""The strategies of bidirectional path tracing: every way of joining a light and a camera subpath.

A lane holds a light subpath y_0 .. y_{nL-1} and a camera subpath
z_0 .. z_{nE-1} (see :mod:`pathspace.integrators.subpaths`).  Strategy
(s, t) forms the path x_0 .. x_k, k = s + t - 1 segments, from y_0 .. y_{s-1}
and z_{t-1} .. z_0 (Veach 1997, ch. 10; pbrt-v3's ConnectBDPT):

* s = 0: the camera subpath found a light itself (an emitting surface or the
  environment at infinity);
* s = 1: a fresh light sample joined to z_{t-1} (next-event estimation);
* t = 1: a fresh lens sample joined to y_{s-1} (light tracing; splatted);
* t = 0: the light subpath passed through a thin lens (splatted);
* s, t >= 2: y_{s-1} and z_{t-1} joined by a shadow ray.

Each function returns the *unweighted* contributions C*_{s,t} (Veach 1997,
eq. 10.8) of every connection that carries any, as :class:`Contributions`,
with what the MIS kernel needs: the densities that the connection changes
(of the connection vertices x_{s-1} = "qs" and x_s = "pt" and their
neighbours; see ``ext/mis.c``) and the flags of the path's light.  Only
connections of at most ``max_depth`` segments are formed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..bsdfs import MaterialLanes, Surface
from ..vecmath import dot
from .bdpt_mis import LIGHT_DELTA, Connections
from .subpaths import LIGHT, SURFACE, LensHits, Subpaths, light_flags, reverse_pdf, to_area
from .visibility import light_sample_blocked, segment_blocked

__all__ = ["Batch", "Contributions", "emitter_hits", "light_samples", "lens_samples", "lens_hits", "joins"]

# General connections are formed and evaluated in chunks of at most this many.
CHUNK = 1 << 17


@dataclass
class Batch:
    """The subpaths of a batch of lanes and what every strategy reads."""

    scene: object
    light: Subpaths
    eye: Subpaths | None
    lens: LensHits | None
    colours: object
    options: dict
    max_depth: int     # segments
    rays: int = 0      # shadow rays traced
    nonfinite: int = 0  # contributions dropped because a channel or their weight was NaN or infinite

    def __post_init__(self) -> None:
        self.lane_flags = light_flags(self.scene, self.light.entity.take(self.light.offset[:-1]))


@dataclass
class Contributions(Connections):
    """Unweighted contributions of connections, one column each, with their MIS inputs (the
    :class:`Connections` fields: strategy, lane, changed densities)."""

    value: np.ndarray         # (C, n)
    raster: np.ndarray        # (2, n) film position of splats (t <= 1); NaN for the lane's own pixel
    flags: np.ndarray         # (n,) uint8 light flags

    @classmethod
    def make(cls, lane, s, t, value, raster=None, **densities) -> "Contributions":
        n = lane.size
        zero = np.zeros(n)
        return cls(lane=lane, s=np.broadcast_to(s, n).astype(np.int32), t=np.broadcast_to(t, n).astype(np.int32),
                   value=value, raster=np.full((2, n), np.nan) if raster is None else raster,
                   **{name: densities.get(name, zero) for name in ("qs_fwd", "qs_rev", "qs_minus_rev", "pt_fwd",
                                                                   "pt_rev", "pt_minus_rev")},
                   flags=densities["flags"])

    @property
    def count(self) -> int:
        return int(self.lane.size)


def _useful(batch: Batch, value: np.ndarray) -> np.ndarray:
    """Indices of the contributions (C, n) worth weighting: non-zero and finite; the non-finite ones
    are counted in ``batch.nonfinite`` (they never reach the film)."""
    finite = np.isfinite(value).all(axis=0)
    batch.nonfinite += int(finite.size - np.count_nonzero(finite))
    return np.flatnonzero((value != 0).any(axis=0) & finite)


def _material_lanes(batch: Batch, sub: Subpaths, v: np.ndarray, lanes: np.ndarray) -> MaterialLanes:
    """The materials of vertices ``v`` (of lanes ``lanes``)."""
    return MaterialLanes(batch.scene.materials, sub.material.take(v), batch.colours.take(lanes), batch.options)


def _materials(batch: Batch, sub: Subpaths, v: np.ndarray, lanes: np.ndarray):
    """Materials and surfaces (seen from the previous vertex) of vertices ``v``, their normals and ``wo``."""
    n = np.take(sub.n, v, axis=1)
    wo = np.take(sub.wo, v, axis=1)
    return _material_lanes(batch, sub, v, lanes), Surface.facing(n, -wo), n, wo


def _density_at_previous(pdf_sa: np.ndarray, sub: Subpaths, v: np.ndarray) -> np.ndarray:
    """A solid-angle density at vertex ``v`` of the direction toward its previous vertex, as an area
    density there (kept in solid angle where that vertex is at infinity; see ``Subpaths.g_prev``)."""
    return pdf_sa * sub.g_prev.take(v)


# -- s = 0 -----------------------------------------------------------------------------------------

def emitter_hits(batch: Batch) -> Contributions | None:
    """Camera vertices z_{t-1} (t >= 2) on emitting surfaces or at infinity in the environment."""
    scene, eye = batch.scene, batch.eye
    lights = scene.lights
    found = (eye.index >= 1) & (eye.index <= batch.max_depth) & (eye.entity >= 0)
    v = np.flatnonzero(found)
    if not v.size:
        return None
    lane, entity, infinite = eye.lane.take(v), eye.entity.take(v), eye.infinite.take(v)
    n, wo = np.take(eye.n, v, axis=1), np.take(eye.wo, v, axis=1)
    colours = batch.colours.take(lane)
    le = np.zeros((colours.channels, v.size))
    at_infinity = np.flatnonzero(infinite)
    on_surface = np.flatnonzero(~infinite)
    if on_surface.size:
        le[:, on_surface] = lights.area.emitted(
            lights.index.take(entity.take(on_surface)), dot(np.take(n, on_surface, axis=1),
                                                            np.take(wo, on_surface, axis=1)),
            colours.take(on_surface))
    if at_infinity.size:
        le[:, at_infinity] = lights.environment_radiance(at_infinity.size, colours.take(at_infinity))
    value = np.take(eye.beta, v, axis=1) * le
    keep = _useful(batch, value)
    v, lane, entity, n, wo, value = v[keep], lane[keep], entity[keep], n[:, keep], wo[:, keep], value[:, keep]
    # The light walk would start here (pt_rev) and go on to z_{t-2} (pt_minus_rev): emission's directional
    # density, or from infinity the disk density times |cos| there.
    pt_minus_rev = _density_at_previous(lights.emission_pdf_dir(entity, n, wo), eye, v)
    return Contributions.make(lane, 0, eye.index.take(v) + 1, value, pt_fwd=eye.fwd.take(v),
                              pt_rev=lights.origin_pdf(entity), pt_minus_rev=pt_minus_rev,
                              flags=light_flags(scene, entity))


# -- s = 1 -----------------------------------------------------------------------------------------

def light_samples(batch: Batch) -> Contributions | None:
    """Camera vertices z_{t-1} (t >= 2) joined to a fresh light sample (next-event estimation)."""
    scene, eye = batch.scene, batch.eye
    lights = scene.lights
    if not lights.count:
        return None
    can = (eye.kind == SURFACE) & ~eye.delta & (eye.index + 1 <= batch.max_depth)
    v = np.flatnonzero(can)
    if not v.size:
        return None
    lane = eye.lane.take(v)
    p = np.take(eye.p, v, axis=1)
    colours = batch.colours.take(lane)
    ls = lights.sample(p, np.take(eye.u, v, axis=1), colours, "power", "area")
    materials, surface, n, wo = _materials(batch, eye, v, lane)
    f_cos, pdf_bsdf = materials.eval(surface, ls.wi)
    with np.errstate(divide="ignore", invalid="ignore"):
        value = np.where(ls.facing & (ls.pdf > 0), np.take(eye.beta, v, axis=1) * f_cos * ls.value / ls.pdf, 0.0)
    useful = _useful(batch, value)
    batch.rays += useful.size
    useful = useful[~light_sample_blocked(scene, p, eye.eps.take(v), n, ls, useful)]
    if not useful.size:
        return None
    v, lane, value, pdf_bsdf = v[useful], lane[useful], value[:, useful], pdf_bsdf[useful]
    n, wo, wi, q = n[:, useful], wo[:, useful], ls.wi[:, useful], eye.q.take(v)
    entity, normal, distance = ls.entity[useful], ls.normal[:, useful], ls.distance[useful].astype(np.float64)
    infinite = ~np.isfinite(distance)
    dist2 = np.where(infinite, 1.0, distance * distance)
    # qs = the light point: its origin density, and the camera walk's density of reaching it from z_{t-1}.
    qs_rev = np.where(infinite, pdf_bsdf * q, to_area(pdf_bsdf * q, normal, wi, dist2))
    # pt = z_{t-1} as the light walk would reach it: emission toward it, to area (from infinity: disk x |cos|).
    pdf_emit = lights.emission_pdf_dir(entity, normal, -wi)
    cos_here = np.abs(dot(n, wi)).astype(np.float64)
    pt_rev = np.where(infinite, pdf_emit * cos_here, to_area(pdf_emit, n, wi, dist2))
    pt_minus_rev = _density_at_previous(reverse_pdf(_material_lanes(batch, eye, v, lane), n, wi, wo) * q, eye, v)
    return Contributions.make(lane, 1, eye.index.take(v) + 1, value, qs_fwd=lights.origin_pdf(entity),
                              qs_rev=qs_rev, pt_fwd=eye.fwd.take(v), pt_rev=pt_rev, pt_minus_rev=pt_minus_rev,
                              flags=light_flags(scene, entity))


# -- t = 1 -----------------------------------------------------------------------------------------

def lens_samples(batch: Batch) -> Contributions | None:
    """Light vertices y_{s-1} joined to a fresh point on the lens (light tracing), splatted."""
    scene, light = batch.scene, batch.light
    camera, lights = scene.camera, scene.lights
    # Lights seen directly: area lights only.  A point or spot light would land in a single pixel as
    # I / (d^2 x the pixel's solid angle); path tracing cannot see it, and neither image draws it.
    on_light = (light.kind == LIGHT) & ~light.infinite & (light.entity < lights.area.count)
    can = ((light.kind == SURFACE) & ~light.delta | on_light) & (light.index + 1 <= batch.max_depth)
    v = np.flatnonzero(can)
    if not v.size:
        return None
    lane = light.lane.take(v)
    p = np.take(light.p, v, axis=1)
    wi, we, pdf_lens, lens, raster, valid = camera.sample_importance(p, np.take(light.u, v, axis=1))
    n = np.take(light.n, v, axis=1)
    value = np.zeros((batch.colours.channels, v.size))
    pdf_fwd = np.zeros(v.size)  # density at y_{s-1} of the direction to the lens
    source = np.flatnonzero(on_light.take(v))
    surface = np.flatnonzero(~on_light.take(v))
    beta = np.take(light.beta, v, axis=1)
    if source.size:
        ent = light.entity.take(v.take(source))
        value[:, source] = lights.emitted_toward(ent, np.take(n, source, axis=1), np.take(wi, source, axis=1),
                                                 batch.colours.take(lane.take(source)))
        pdf_fwd[source] = lights.emission_pdf_dir(ent, np.take(n, source, axis=1), np.take(wi, source, axis=1))
    pdf_back = np.zeros(v.size)  # density at y_{s-1} of the direction to y_{s-2}, light arriving from the lens
    if surface.size:
        vs = v.take(surface)
        materials, surf, ns, wo = _materials(batch, light, vs, lane.take(surface))
        wis = np.take(wi, surface, axis=1)
        value[:, surface], pdf_fwd[surface] = materials.eval(surf, wis)
        pdf_back[surface] = reverse_pdf(materials, ns, wis, wo)
    with np.errstate(divide="ignore", invalid="ignore"):
        value = np.where(valid & (pdf_lens > 0), beta * value * (we / pdf_lens), 0.0)
    useful = _useful(batch, value)
    batch.rays += useful.size
    lens32 = np.take(lens, useful, axis=1).astype(np.float32)
    axis = np.repeat(camera.forward.astype(np.float32)[:, None], useful.size, axis=1)
    blocked = segment_blocked(scene, np.take(p, useful, axis=1), light.eps.take(v.take(useful)),
                              np.take(n, useful, axis=1), lens32, np.zeros(useful.size, np.float32),
                              axis if not camera.delta_position else np.zeros_like(axis))
    useful = useful[~blocked]
    if not useful.size:
        return None
    v, lane, value, wi, n, q = v[useful], lane[useful], value[:, useful], wi[:, useful], n[:, useful], light.q.take(
        v[useful])
    lens, pdf_fwd, pdf_back = lens[:, useful], pdf_fwd[useful], pdf_back[useful]
    d = lens - np.take(light.p, v, axis=1)
    dist2 = dot(d, d)
    axis = np.repeat(camera.forward[:, None], v.size, axis=1)
    # pt = the lens point: the camera's positional density, and the light walk's density of reaching it.
    pt_rev = to_area(pdf_fwd * q, axis, wi, dist2)
    # qs = y_{s-1} as the camera walk would reach it from the lens point: the direction's density
    # 1 / (A cos^3) is We lens_area cos (see pathspace.camera).
    we = we[useful]
    qs_rev = to_area(we * camera.lens_area * np.abs(camera.cos_to_axis(-wi)), n, wi, dist2)
    # y_{s-2} as the camera walk would go on to it (nothing for s = 1: pdf_back and g_prev are 0 there).
    qs_minus_rev = _density_at_previous(pdf_back * q, light, v)
    return Contributions.make(lane, light.index.take(v) + 1, 1, value, raster=raster[:, useful],
                              qs_fwd=light.fwd.take(v), qs_rev=qs_rev, qs_minus_rev=qs_minus_rev,
                              pt_fwd=np.full(v.size, 1.0 / camera.lens_area), pt_rev=pt_rev,
                              flags=batch.lane_flags.take(lane))


# -- t = 0 -----------------------------------------------------------------------------------------

def lens_hits(batch: Batch) -> Contributions | None:
    """Light-walk rays that pass through a thin lens: the lens is the path's last vertex, splatted."""
    scene, light, hits = batch.scene, batch.light, batch.lens
    camera = scene.camera
    if hits is None or not hits.lane.size:
        return None
    # A point or spot light seen directly through the lens is not drawn (see lens_samples).
    direct_delta = (hits.index == 1) & (batch.lane_flags.take(hits.lane) & LIGHT_DELTA).astype(bool)
    keep = np.flatnonzero((hits.index <= batch.max_depth) & ~direct_delta)
    lane, index, point, d = hits.lane[keep], hits.index[keep], hits.point[:, keep], hits.direction[:, keep]
    leaving = -d.astype(np.float64)
    raster, inside = camera.raster(point + leaving, point)
    value = np.where(inside, hits.beta[:, keep] * camera.importance(leaving, point), 0.0)
    useful = _useful(batch, value)
    if not useful.size:
        return None
    lane, index, point, leaving, value, raster = (lane[useful], index[useful], point[:, useful], leaving[:, useful],
                                                  value[:, useful], raster[:, useful])
    pdf, distance = hits.pdf[keep][useful], hits.distance[keep][useful].astype(np.float64)
    prev = light.offset.take(lane) + index - 1
    prev_infinite = light.infinite.take(prev)
    cos_lens = np.abs(camera.cos_to_axis(leaving))
    with np.errstate(divide="ignore", invalid="ignore"):
        qs_fwd = pdf * cos_lens / np.where(prev_infinite, 1.0, distance * distance)
    # y_{s-2} as the camera walk would reach it from this lens point.
    pdf_camera = camera.pdf_direction(leaving, point)
    qs_minus_rev = np.where(prev_infinite, pdf_camera,
                            to_area(pdf_camera, np.take(light.n, prev, axis=1), leaving, distance * distance))
    return Contributions.make(lane, index + 1, 0, value, raster=raster, qs_fwd=qs_fwd,
                              qs_rev=np.full(lane.size, 1.0 / camera.lens_area), qs_minus_rev=qs_minus_rev,
                              flags=batch.lane_flags.take(lane))


# -- s, t >= 2 -------------------------------------------------------------------------------------

def joins(batch: Batch):
    """Every pair of non-delta surface vertices y_{s-1}, z_{t-1} (s, t >= 2) of a lane, joined; yields
    :class:`Contributions` chunk by chunk."""
    light, eye = batch.light, batch.eye
    cy = np.flatnonzero((light.kind == SURFACE) & ~light.delta)
    cz = np.flatnonzero((eye.kind == SURFACE) & ~eye.delta)
    lanes = light.offset.size - 1
    ny = np.bincount(light.lane.take(cy), minlength=lanes)
    nz = np.bincount(eye.lane.take(cz), minlength=lanes)
    pairs = ny * nz
    total = int(pairs.sum())
    if not total:
        return
    y_start = np.concatenate([[0], np.cumsum(ny)[:-1]])
    z_start = np.concatenate([[0], np.cumsum(nz)[:-1]])
    pair_start = np.concatenate([[0], np.cumsum(pairs)[:-1]])
    for begin in range(0, total, CHUNK):
        k = np.arange(begin, min(begin + CHUNK, total))
        lane = np.searchsorted(pair_start, k, side="right") - 1
        # Lanes without pairs share their start with the next lane; searchsorted picks the last of them.
        local = k - pair_start.take(lane)
        y = cy.take(y_start.take(lane) + local // nz.take(lane))
        z = cz.take(z_start.take(lane) + local % nz.take(lane))
        s, t = light.index.take(y) + 1, eye.index.take(z) + 1
        ok = s + t - 1 <= batch.max_depth
        if not ok.all():
            lane, y, z, s, t = lane[ok], y[ok], z[ok], s[ok], t[ok]
        if lane.size:
            part = _join(batch, lane, y, z, s, t)
            if part is not None:
                yield part


def _join(batch: Batch, lane, y, z, s, t) -> Contributions | None:
    scene, light, eye = batch.scene, batch.light, batch.eye
    py, pz = np.take(light.p, y, axis=1), np.take(eye.p, z, axis=1)
    d = pz.astype(np.float64) - py
    dist2 = dot(d, d)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = (d / np.sqrt(dist2)).astype(np.float32)  # y -> z
    mat_y, surf_y, ny, wo_y = _materials(batch, light, y, lane)
    mat_z, surf_z, nz, wo_z = _materials(batch, eye, z, lane)
    f_y, pdf_y = mat_y.eval(surf_y, w)
    f_z, pdf_z = mat_z.eval(surf_z, -w)
    with np.errstate(divide="ignore", invalid="ignore"):
        value = np.where(dist2 > 0, np.take(light.beta, y, axis=1) * f_y * f_z * np.take(eye.beta, z, axis=1) / dist2,
                         0.0)
    useful = _useful(batch, value)
    batch.rays += useful.size
    blocked = segment_blocked(scene, np.take(py, useful, axis=1), light.eps.take(y.take(useful)),
                              np.take(ny, useful, axis=1), np.take(pz, useful, axis=1), eye.eps.take(z.take(useful)),
                              np.take(nz, useful, axis=1))
    useful = useful[~blocked]
    if not useful.size:
        return None
    pick = lambda a: np.take(a, useful, axis=-1)  # noqa: E731
    lane, y, z, s, t, value, w, dist2 = map(pick, (lane, y, z, s, t, value, w, dist2))
    ny, nz, wo_y, wo_z, pdf_y, pdf_z = map(pick, (ny, nz, wo_y, wo_z, pdf_y, pdf_z))
    q_y, q_z = light.q.take(y), eye.q.take(z)
    mat_y, mat_z = _material_lanes(batch, light, y, lane), _material_lanes(batch, eye, z, lane)
    return Contributions.make(
        lane, s, t, value,
        qs_fwd=light.fwd.take(y), qs_rev=to_area(pdf_z * q_z, ny, w, dist2),
        qs_minus_rev=_density_at_previous(reverse_pdf(mat_y, ny, w, wo_y) * q_y, light, y),
        pt_fwd=eye.fwd.take(z), pt_rev=to_area(pdf_y * q_y, nz, w, dist2),
        pt_minus_rev=_density_at_previous(reverse_pdf(mat_z, nz, -w, wo_z) * q_z, eye, z),
        flags=batch.lane_flags.take(lane))
