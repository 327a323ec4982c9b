"""The strategies of bidirectional path tracing: every way of joining a light and a camera subpath.

A lane holds a light subpath y_0 .. y_{nL-1} and a camera subpath
z_0 .. z_{nE-1} (see :mod:`pathspace.estimators.subpaths`).  Strategy
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
connections of at most ``max_depth`` segments are formed.  ``y`` and ``z``
below are views (:class:`~pathspace.estimators.subpaths.Vertices`) of the
connection vertices.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import _native
from ..bsdfs import MaterialLanes, Surface
from ..mis import LIGHT_DELTA, Connections
from ..vecmath import dot
from .join_fused import JoinKernel, LightSampleKernel
from .lens_fused import LensKernel
from .subpaths import (LIGHT, LIGHT_SELECTION, SURFACE, LensHits, Subpaths, Vertices, area_density, cos_at,
                       reverse_pdf, to_area)
from .visibility import light_sample_blocked, segment_blocked

__all__ = ["Batch", "Contributions", "emitter_hits", "light_samples", "lens_samples", "lens_hits", "joins",
           "CHUNK"]

# General connections are formed and evaluated in chunks of at most this many.
CHUNK = 1 << 17


@dataclass
class Batch:
    """The subpaths of a batch of lanes and what every strategy reads.  ``units`` (lanes + 1,): the lanes
    of unit j (one pass of one tile) are ``units[j]`` .. ``units[j+1] - 1``; joins are chunked unit by
    unit, so that a unit's results do not depend on what else shares the batch.  A light tracer's batch
    holds only the light vertices 0 in ``light`` and, in ``made``, the connections it made while the subpaths
    were walked."""

    scene: object
    light: Subpaths
    eye: Subpaths | None
    lens: LensHits | None
    colours: object
    options: dict
    max_depth: int     # segments
    units: np.ndarray
    densities: bool = True  # whether connections carry the densities MIS weights read (light tracing: no)
    rays: int = 0      # shadow rays traced
    nonfinite: int = 0  # contributions dropped because a channel or their weight was NaN or infinite
    chosen: tuple[np.ndarray, np.ndarray] | None = None   # (s, t) per lane: only that strategy (MMLT); None: all
    made: list[Contributions] | None = None  # connections made while the subpaths were walked (light tracing)
    lens_kernel: LensKernel | None = None    # joins light vertices to the camera in C (see estimators.lens_fused)
    join_kernel: JoinKernel | None = None    # joins light and camera vertices in C (see estimators.join_fused)
    light_kernel: LightSampleKernel | None = None  # joins camera vertices to light samples in C (the same)

    def __post_init__(self) -> None:
        self.lane_flags = self.scene.lights.flags.take(self.light.entity.take(self.light.offset[:-1]))

    def wanted(self, lane: np.ndarray, s, t) -> np.ndarray | bool:
        """Whether the strategies (s, t) of connections of ``lane`` are to be computed (all, unless ``chosen``)."""
        if self.chosen is None:
            return True
        return (self.chosen[0].take(lane) == s) & (self.chosen[1].take(lane) == t)

    def materials(self, vertices: Vertices) -> MaterialLanes:
        """The materials of surface ``vertices``."""
        return MaterialLanes(self.scene.materials, vertices.material, self.colours.take(vertices.lane), self.options)

    def useful(self, value: np.ndarray) -> np.ndarray:
        """Indices of the contributions (C, n) worth weighting: non-zero and finite; the non-finite ones
        are counted in ``nonfinite`` (they never reach the film).  One C pass (``ext/lanes.c``)."""
        useful, nonfinite = _native.useful_lanes(np.ascontiguousarray(value, np.float64))
        self.nonfinite += nonfinite
        return useful


@dataclass
class Contributions(Connections):
    """Unweighted contributions of connections, one column each, with their MIS inputs (the
    :class:`~pathspace.mis.Connections` fields: strategy, lane, changed densities)."""

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


def _surface(vertices: Vertices) -> Surface:
    """The shading frame of ``vertices`` seen from their previous vertex."""
    return Surface.facing(vertices.n, -vertices.wo)


def _at_previous(pdf_sa: np.ndarray, vertices: Vertices) -> np.ndarray:
    """A solid-angle density at ``vertices`` of the direction toward their previous vertex, as an area
    density there (kept in solid angle where that vertex is at infinity; see ``Subpaths.g_prev``)."""
    return pdf_sa * vertices.g_prev


# -- s = 0 -----------------------------------------------------------------------------------------

def emitter_hits(batch: Batch) -> Contributions | None:
    """Camera vertices z_{t-1} (t >= 2) on emitting surfaces or at infinity in the environment."""
    eye, lights = batch.eye, batch.scene.lights
    z = eye.at(np.flatnonzero((eye.index >= 1) & (eye.index <= batch.max_depth) & (eye.entity >= 0)
                              & batch.wanted(eye.lane, 0, eye.index + 1)))
    if not z.size:
        return None
    value = z.beta * lights.le(z.entity, z.n, z.wo, batch.colours.take(z.lane))
    z, value = _kept(batch, z, value)
    # The light walk would start here (pt_rev) and go on to z_{t-2} (pt_minus_rev): emission's directional
    # density, or from infinity the disk density times |cos| there.
    origin, pdf_dir = lights.pdf_le(z.entity, z.n, z.wo)
    return Contributions.make(z.lane, 0, z.index + 1, value, pt_fwd=z.fwd, pt_rev=origin,
                              pt_minus_rev=_at_previous(pdf_dir, z), flags=lights.flags.take(z.entity))


def _kept(batch: Batch, vertices: Vertices, value: np.ndarray) -> tuple[Vertices, np.ndarray]:
    """The vertices and values (C, n) of the useful contributions (see :meth:`Batch.useful`)."""
    keep = batch.useful(value)
    return vertices.keep(keep), np.take(value, keep, axis=1)


# -- s = 1 -----------------------------------------------------------------------------------------

def light_samples(batch: Batch) -> Contributions | None:
    """Camera vertices z_{t-1} (t >= 2) joined to a fresh light sample (next-event estimation)."""
    scene, eye = batch.scene, batch.eye
    lights = scene.lights
    if not lights.count:
        return None
    z = eye.at(np.flatnonzero((eye.kind == SURFACE) & ~eye.delta & (eye.index + 1 <= batch.max_depth)
                              & batch.wanted(eye.lane, 1, eye.index + 1)))
    if not z.size:
        return None
    if batch.light_kernel is not None:   # area lights, diffuse vertices: the contributions and densities in C
        return _light_samples_joined(batch, z)
    ls = lights.sample_li(z.p, z.u, batch.colours.take(z.lane), LIGHT_SELECTION, "area")
    f_cos, pdf_bsdf = batch.materials(z).eval(_surface(z), ls.wi)
    with np.errstate(divide="ignore", invalid="ignore"):
        value = np.where(ls.facing & (ls.pdf > 0), z.beta * f_cos * ls.value / ls.pdf, 0.0)
    useful = batch.useful(value)
    batch.rays += useful.size
    useful = useful[~light_sample_blocked(scene, z.p, z.eps, z.n, ls, useful)]
    if not useful.size:
        return None
    z, value, pdf_bsdf = z.keep(useful), np.take(value, useful, axis=1), pdf_bsdf[useful]
    wi, entity, normal = np.take(ls.wi, useful, axis=1), ls.entity[useful], np.take(ls.normal, useful, axis=1)
    distance = ls.distance[useful].astype(np.float64)
    infinite = ~np.isfinite(distance)
    dist2 = np.where(infinite, 1.0, distance * distance)
    # qs = the light point: its origin density, and the camera walk's density of reaching it from z_{t-1}.
    qs_rev = np.where(infinite, pdf_bsdf * z.q, to_area(pdf_bsdf * z.q, normal, wi, dist2))
    # pt = z_{t-1} as the light walk would reach it: emission toward it, to area (from infinity: disk x |cos|).
    origin, pdf_emit = lights.pdf_le(entity, normal, -wi, LIGHT_SELECTION)
    cos_here = np.abs(dot(z.n, wi)).astype(np.float64)
    pt_rev = np.where(infinite, pdf_emit * cos_here, to_area(pdf_emit, z.n, wi, dist2))
    pt_minus_rev = _at_previous(reverse_pdf(batch.materials(z), z.n, wi, z.wo) * z.q_rev, z)
    return Contributions.make(z.lane, 1, z.index + 1, value, qs_fwd=origin, qs_rev=qs_rev, pt_fwd=z.fwd,
                              pt_rev=pt_rev, pt_minus_rev=pt_minus_rev, flags=lights.flags.take(entity))


def _light_samples_joined(batch: Batch, z: Vertices) -> Contributions | None:
    """:func:`light_samples` of camera vertices ``z`` through ``batch.light_kernel`` (bit for bit the same)."""
    eye = batch.eye
    joined = batch.light_kernel(eye, z.v)
    useful = batch.useful(joined.value)
    batch.rays += useful.size
    useful = useful[~segment_blocked(batch.scene, eye.p, eye.eps, eye.n, joined.point, joined.epsilon, joined.normal,
                                     z.v.take(useful), useful)]
    if not useful.size:
        return None
    z = z.keep(useful)
    densities = {name: getattr(joined, name)[useful] for name in ("qs_fwd", "qs_rev", "pt_rev", "pt_minus_rev")}
    return Contributions.make(z.lane, 1, z.index + 1, np.take(joined.value, useful, axis=1), pt_fwd=z.fwd,
                              **densities, flags=batch.scene.lights.flags.take(joined.entity[useful]))


# -- t = 1 -----------------------------------------------------------------------------------------

def lens_samples(batch: Batch, light: Subpaths | None = None) -> Contributions | None:
    """Light vertices y_{s-1} joined to a fresh point on the lens (light tracing), splatted: those of ``light``
    (default: the batch's light subpaths)."""
    scene, light = batch.scene, batch.light if light is None else light
    camera, lights = scene.camera, scene.lights
    # Lights seen directly: area lights only.  A point or spot light would land in a single pixel as
    # I / (d^2 x the pixel's solid angle); path tracing cannot see it, and neither image draws it.
    on_light = (light.kind == LIGHT) & (light.entity >= 0) & ~(lights.flags.take(np.maximum(light.entity, 0)) > 0)
    y = light.at(np.flatnonzero(((light.kind == SURFACE) & ~light.delta | on_light) & (light.index + 1 <= batch.max_depth)
                                & batch.wanted(light.lane, light.index + 1, 1)))
    if not y.size:
        return None
    if batch.lens_kernel is not None:   # a pinhole: the contributions (and the densities) in C
        joined = batch.lens_kernel(light, y.v, on_light.take(y.v), batch.densities)
        value, raster = joined.value, joined.raster
    else:
        joined = None
        wi, we, pdf_lens, lens, raster, valid = camera.sample_importance(y.p, y.u)
        value, pdf_fwd, pdf_back = _toward_lens(batch, y, on_light.take(y.v), wi, batch.densities)
        with np.errstate(divide="ignore", invalid="ignore"):
            value = np.where(valid & (pdf_lens > 0), y.beta * value * (we / pdf_lens), 0.0)
    useful = batch.useful(value)
    batch.rays += useful.size
    if joined is not None:   # the pinhole: one lens point
        lens32 = np.repeat(camera.position.astype(np.float32)[:, None], useful.size, axis=1)
    else:
        lens32 = np.take(lens, useful, axis=1).astype(np.float32)
    axis = (np.zeros((3, useful.size), np.float32) if camera.delta_position
            else np.repeat(camera.forward.astype(np.float32)[:, None], useful.size, axis=1))
    unblocked = np.flatnonzero(~segment_blocked(scene, light.p, light.eps, light.n, lens32,
                                                np.zeros(useful.size, np.float32), axis, y.v.take(useful),
                                                np.arange(useful.size)))
    useful = useful[unblocked]
    if not useful.size:
        return None
    y, value, raster = y.keep(useful), np.take(value, useful, axis=1), np.take(raster, useful, axis=1)
    if not batch.densities:
        return Contributions.make(y.lane, y.index + 1, 1, value, raster=raster, flags=batch.lane_flags.take(y.lane))
    if joined is not None:
        pt_rev, qs_minus_rev, qs_rev = (getattr(joined, name)[useful] for name in ("pt_rev", "qs_minus_rev", "qs_rev"))
    else:
        wi, lens = np.take(wi, useful, axis=1), np.take(lens, useful, axis=1)
        d = lens - y.p
        dist2 = dot(d, d)
        axis = np.repeat(camera.forward[:, None], y.size, axis=1)
        # pt = the lens point: the camera's positional density, and the light walk's density of reaching it.
        pt_rev = to_area(pdf_fwd[useful] * y.q, axis, wi, dist2)
        # y_{s-2} as the camera walk would go on to it (nothing for s = 1: pdf_back and g_prev are 0 there).
        qs_minus_rev = _at_previous(pdf_back[useful] * y.q_rev, y)
        # qs = y_{s-1} as the camera walk would reach it from the lens point: the direction's density
        # 1 / (A cos^3) is We lens_area cos (see pathspace.camera).
        qs_rev = area_density(we[useful] * camera.lens_area * np.abs(camera.cos_to_axis(-wi)), cos_at(y.n, wi), dist2)
    return Contributions.make(y.lane, y.index + 1, 1, value, raster=raster, qs_fwd=y.fwd, qs_rev=qs_rev,
                              qs_minus_rev=qs_minus_rev, pt_fwd=np.full(y.size, 1.0 / camera.lens_area),
                              pt_rev=pt_rev, flags=batch.lane_flags.take(y.lane))


def _toward_lens(batch: Batch, y: Vertices, on_light: np.ndarray, wi: np.ndarray, reverse: bool = True):
    """What light vertices ``y`` send toward the lens along ``wi`` (f |cos|, or emission |cos|), the density
    of that direction at y, and the density at y of the direction to y_{s-2}, light arriving from the lens
    (zero unless ``reverse``)."""
    value = np.zeros((batch.colours.channels, y.size))
    pdf_fwd, pdf_back = np.zeros(y.size), np.zeros(y.size)
    source, surface = np.flatnonzero(on_light), np.flatnonzero(~on_light)
    if source.size:
        lights, ys = batch.scene.lights, y.keep(source)
        w = np.take(wi, source, axis=1)
        value[:, source] = lights.le(ys.entity, ys.n, w, batch.colours.take(ys.lane)) * cos_at(ys.n, w)
        pdf_fwd[source] = lights.pdf_le(ys.entity, ys.n, w)[1]
    if surface.size:
        ys = y.keep(surface)
        materials, w = batch.materials(ys), np.take(wi, surface, axis=1)
        value[:, surface], pdf_fwd[surface] = materials.eval(_surface(ys), w)
        if reverse:
            pdf_back[surface] = reverse_pdf(materials, ys.n, w, ys.wo)
    return value, pdf_fwd, pdf_back


# -- t = 0 -----------------------------------------------------------------------------------------

def lens_hits(batch: Batch) -> Contributions | None:
    """Light-walk rays that pass through a thin lens: the lens is the path's last vertex, splatted."""
    scene, light, hits = batch.scene, batch.light, batch.lens
    camera = scene.camera
    if hits is None or not hits.lane.size:
        return None
    # A point or spot light seen directly through the lens is not drawn (see lens_samples).
    direct_delta = (hits.index == 1) & (batch.lane_flags.take(hits.lane) & LIGHT_DELTA).astype(bool)
    keep = np.flatnonzero((hits.index <= batch.max_depth) & ~direct_delta & batch.wanted(hits.lane, hits.index + 1, 0))
    lane, index = hits.lane[keep], hits.index[keep]
    point, d = np.take(hits.point, keep, axis=1), np.take(hits.direction, keep, axis=1)
    leaving = -d.astype(np.float64)
    raster, inside = camera.raster(point + leaving, point)
    value = np.where(inside, np.take(hits.beta, keep, axis=1) * camera.importance(leaving, point), 0.0)
    useful = batch.useful(value)
    if not useful.size:
        return None
    lane, index, point, leaving, value, raster = (lane[useful], index[useful], np.take(point, useful, axis=1),
                                                  np.take(leaving, useful, axis=1), np.take(value, useful, axis=1),
                                                  np.take(raster, useful, axis=1))
    pdf, distance = hits.pdf[keep][useful], hits.distance[keep][useful].astype(np.float64)
    y = light.at(light.offset.take(lane) + index - 1)  # the last light vertex before the lens
    cos_lens = np.abs(camera.cos_to_axis(leaving))
    with np.errstate(divide="ignore", invalid="ignore"):
        qs_fwd = pdf * cos_lens / np.where(y.infinite, 1.0, distance * distance)
    # y_{s-2} as the camera walk would reach it from this lens point.
    pdf_camera = camera.pdf_direction(leaving, point)
    qs_minus_rev = np.where(y.infinite, pdf_camera, to_area(pdf_camera, y.n, leaving, distance * distance))
    return Contributions.make(lane, index + 1, 0, value, raster=raster, qs_fwd=qs_fwd,
                              qs_rev=np.full(lane.size, 1.0 / camera.lens_area), qs_minus_rev=qs_minus_rev,
                              flags=batch.lane_flags.take(lane))


# -- s, t >= 2 -------------------------------------------------------------------------------------

def joins(batch: Batch):
    """Every pair of non-delta surface vertices y_{s-1}, z_{t-1} (s, t >= 2) of a lane, joined; yields
    :class:`Contributions` chunk by chunk (chunks never span two units)."""
    light, eye = batch.light, batch.eye
    if batch.chosen is not None:
        yield from _chosen_joins(batch)
        return
    cy = np.flatnonzero((light.kind == SURFACE) & ~light.delta)
    cz = np.flatnonzero((eye.kind == SURFACE) & ~eye.delta)
    lanes = light.offset.size - 1
    ny = np.bincount(light.lane.take(cy), minlength=lanes)
    nz = np.bincount(eye.lane.take(cz), minlength=lanes)
    pairs = ny * nz
    if not pairs.any():
        return
    y_start = np.concatenate([[0], np.cumsum(ny)[:-1]])
    z_start = np.concatenate([[0], np.cumsum(nz)[:-1]])
    pair_start = np.concatenate([[0], np.cumsum(pairs)])
    for first, last in zip(batch.units[:-1], batch.units[1:]):
        for begin in range(int(pair_start[first]), int(pair_start[last]), CHUNK):
            end = min(begin + CHUNK, int(pair_start[last]))
            # Lane l's pair nz[l] i + j joins its light vertex cy[y_start[l] + i] and camera vertex
            # cz[z_start[l] + j]; those of s + t - 1 <= max_depth segments (one C pass).
            y, z = _native.join_pairs(pair_start, nz, y_start, z_start, cy, cz, light.index, eye.index, begin, end,
                                      batch.max_depth)
            if y.size:
                part = _join(batch, light.at(y), eye.at(z))
                if part is not None:
                    yield part


def _chosen_joins(batch: Batch):
    """The join of each lane's chosen strategy (s, t >= 2), where both subpaths have those vertices."""
    light, eye = batch.light, batch.eye
    s, t = batch.chosen
    lane = np.flatnonzero((s >= 2) & (t >= 2) & (s + t - 1 <= batch.max_depth) & (light.length >= s)
                          & (eye.length >= t))
    y = light.offset.take(lane) + s.take(lane) - 1
    z = eye.offset.take(lane) + t.take(lane) - 1
    ok = (light.kind.take(y) == SURFACE) & ~light.delta.take(y) & (eye.kind.take(z) == SURFACE) & ~eye.delta.take(z)
    y, z, lane = y[ok], z[ok], lane[ok]
    for first, last in zip(batch.units[:-1], batch.units[1:]):
        mine = np.flatnonzero((lane >= first) & (lane < last))
        for begin in range(0, mine.size, CHUNK):
            k = mine[begin:begin + CHUNK]
            part = _join(batch, light.at(y.take(k)), eye.at(z.take(k)))
            if part is not None:
                yield part


def _join(batch: Batch, y: Vertices, z: Vertices) -> Contributions | None:
    """The connections y -> z (views of the same lanes) whose shadow rays are clear."""
    if batch.join_kernel is not None:   # diffuse vertices: the contributions and densities in C
        joined = batch.join_kernel(batch.light, batch.eye, y.v, z.v)
        value = joined.value
    else:
        d = z.p.astype(np.float64) - y.p
        dist2 = dot(d, d)
        with np.errstate(divide="ignore", invalid="ignore"):
            w = (d / np.sqrt(dist2)).astype(np.float32)  # y -> z
        f_y, pdf_y = batch.materials(y).eval(_surface(y), w)
        f_z, pdf_z = batch.materials(z).eval(_surface(z), -w)
        with np.errstate(divide="ignore", invalid="ignore"):
            value = np.where(dist2 > 0, y.beta * f_y * f_z * z.beta / dist2, 0.0)
    useful = batch.useful(value)
    batch.rays += useful.size
    light, eye = batch.light, batch.eye   # the segments' ends read where they are (no gathers)
    useful = useful[~segment_blocked(batch.scene, light.p, light.eps, light.n, eye.p, eye.eps, eye.n,
                                     y.v.take(useful), z.v.take(useful))]
    if not useful.size:
        return None
    y, z, value = y.keep(useful), z.keep(useful), np.take(value, useful, axis=1)
    if batch.join_kernel is not None:
        densities = {name: getattr(joined, name)[useful] for name in ("qs_rev", "qs_minus_rev", "pt_rev",
                                                                      "pt_minus_rev")}
    else:
        dist2, w, pdf_y, pdf_z = dist2[useful], np.take(w, useful, axis=1), pdf_y[useful], pdf_z[useful]
        densities = dict(qs_rev=to_area(pdf_z * z.q, y.n, w, dist2),
                         qs_minus_rev=_at_previous(reverse_pdf(batch.materials(y), y.n, w, y.wo) * y.q_rev, y),
                         pt_rev=to_area(pdf_y * y.q, z.n, w, dist2),
                         pt_minus_rev=_at_previous(reverse_pdf(batch.materials(z), z.n, -w, z.wo) * z.q_rev, z))
    return Contributions.make(y.lane, y.index + 1, z.index + 1, value, qs_fwd=y.fwd, pt_fwd=z.fwd, **densities,
                              flags=batch.lane_flags.take(y.lane))
