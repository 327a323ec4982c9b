"""Camera and light subpaths for bidirectional estimators, generated over wavefronts.

Each lane of a batch grows one subpath by a random walk (Veach 1997, ch. 10;
pbrt-v3's GenerateCameraSubpath / GenerateLightSubpath).  Vertex i of a
subpath records where it is, the throughput ``beta`` of the subpath up to it
(excluding its own scattering), and two densities in area measure:

``fwd``  the density with which this walk generated it (from vertex i-1),
``rev``  the density with which a walk in the opposite direction would have
         generated it (from vertex i+1), filled in once vertex i+1 has
         sampled its direction.

Both include the Russian-roulette continuation probability ``q`` of the
vertex they are generated from, so that multiple importance sampling sees the
real densities.  ``q`` is *local* -- a property of the material at the
vertex, not of the path -- so it is the same in both directions (as in
SmallVCM), and the reverse densities can be stored once.  Densities at points
at infinity (the environment) are in solid angle; the density of a vertex
generated from infinity is the density on the disk the rays start from,
projected (times |cos| at the vertex).  Delta (specular) vertices carry
density 0 toward their neighbours.

Vertices of all lanes are stored flat, lane after lane, with CSR offsets, so
that connections gather any (lane, vertex) pair in one array operation.
Camera walks that leave the scene end in a vertex at infinity when there is
an environment (the s = 0 strategy finds it there); light walks report the
rays that pass through a thin lens (the t = 0 strategy).  Every vertex also
carries the uniforms its connections will use (``u``: a light sample's 3 for
camera vertices, a lens sample's 2 for light vertices), drawn with it, so a
lane's random numbers depend on nothing else in the batch.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..bsdfs import Diffuse, MaterialLanes, Mirror, Phong, Surface
from ..lights import DIRECTIONAL, ENVIRONMENT, POINT, SPOT
from ..spectra import ColourTable
from ..vecmath import dot, leave_distance
from .bdpt_mis import LIGHT_DELTA, LIGHT_INFINITE

__all__ = ["Subpaths", "LensHits", "SURFACE", "CAMERA", "LIGHT", "SAFETY_VERTICES", "ROULETTE", "continuation",
           "camera_subpaths", "light_subpaths", "to_area", "reverse_pdf", "light_flags"]

SURFACE, CAMERA, LIGHT = 0, 1, 2
# Subpaths still growing at this many vertices are cut (and counted): only lossless traps get there.
SAFETY_VERTICES = 10_000
ROULETTE = ("albedo", "fixed", "off")
# Continuation probability at specular (delta) vertices under "albedo": glass loses no energy, and a
# walk can circle inside it by total internal reflection for thousands of bounces (tessellated
# spheres trap some rays); this keeps such chains geometrically short (the weight grows by 1/0.9 per
# bounce, and a chain's variance stays finite while it leaves the glass with probability > 0.1).
DELTA_CONTINUATION = 0.9
FIELDS = ("lane", "index", "p", "n", "eps", "wo", "beta", "fwd", "rev", "g_prev", "delta", "kind", "material",
          "entity", "q", "infinite", "u")
CAMERA_UNIFORMS, LIGHT_UNIFORMS = 3, 2  # per vertex, for its connections
BOUNCE_UNIFORMS = 4                     # BSDF lobe and direction (3), roulette (1)


def to_area(pdf_sa: np.ndarray, normal: np.ndarray, w: np.ndarray, dist2: np.ndarray) -> np.ndarray:
    """Solid-angle densities turned into area densities at targets a distance sqrt(dist2) away along unit
    ``w``: pdf |cos| / d^2 with cos between ``w`` and the target's ``normal`` (a zero normal -- a point
    light -- has no cosine factor)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(dist2 > 0, pdf_sa * _cos_at(normal, w) / dist2, 0.0)


def reverse_pdf(materials: MaterialLanes, n: np.ndarray, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Solid-angle density with which the materials sample ``wo`` when light arrives from ``wi`` (the
    walk in the opposite direction); ``n`` geometric normals."""
    return materials.eval(Surface.facing(n, -wi), wo)[1]


def light_flags(scene, entity: np.ndarray) -> np.ndarray:
    """MIS flags of light entities (see :mod:`pathspace.integrators.bdpt_mis`)."""
    kind = scene.lights.kind.take(entity)
    delta = (kind == POINT) | (kind == SPOT) | (kind == DIRECTIONAL)
    infinite = (kind == DIRECTIONAL) | (kind == ENVIRONMENT)
    return (delta * LIGHT_DELTA + infinite * LIGHT_INFINITE).astype(np.uint8)


def continuation(scene, policy: str, probability: float) -> np.ndarray:
    """Russian-roulette continuation probability q of every material (local: the same in both directions).

    "albedo": the largest channel of the material's albedo bound (diffuse
    and mirror: reflectance; Phong: diffuse + specular; glass and conductors:
    1), at most DELTA_CONTINUATION for specular materials; "fixed": 1 -
    ``probability``; "off": 1.
    """
    if policy not in ROULETTE:
        raise ValueError(f"rr: expected one of {ROULETTE}, got {policy!r}")
    out = np.ones(len(scene.materials))
    if policy == "off":
        return out
    if policy == "fixed":
        return out * (1.0 - probability)
    for m, material in enumerate(scene.materials.materials):
        if isinstance(material, (Diffuse, Mirror)):
            out[m] = ColourTable([material.reflectance], "reflectance").rgb.max()
        elif isinstance(material, Phong):
            kd = ColourTable([material.diffuse], "reflectance").rgb[:, 0]
            ks = ColourTable([material.specular], "reflectance").rgb[:, 0]
            out[m] = min(1.0, float((kd + ks).max()))
        if material.delta:
            out[m] = min(out[m], DELTA_CONTINUATION)
    return out


@dataclass
class Subpaths:
    """Vertices of one kind of subpath (camera or light) for a batch of lanes, flat with CSR offsets.

    Per vertex: ``lane``, ``index`` (position in its subpath), ``p``, ``n``
    (geometric normal; an area light's normal; the lens axis; the direction
    of travel at infinity; zero for point and spot lights), ``eps`` (ray
    offset of its surface), ``wo`` (unit direction toward the previous
    vertex), ``beta`` (C, V), ``fwd``, ``rev``, ``delta``, ``kind`` (SURFACE,
    CAMERA, LIGHT), ``material`` (-1 off surfaces), ``entity`` (the light
    entity of light vertices and of surface vertices on emitters, else -1),
    ``q`` (continuation probability), ``infinite``, ``u`` (its connections'
    uniforms), ``g_prev`` (what turns a solid-angle density of leaving the
    vertex toward its predecessor into an area density there: |cos| / d^2 at
    the predecessor, |cos| alone from a vertex at infinity, 1 toward one).
    ``terminated`` (lanes,): a dispersive interface kept only the hero
    wavelength somewhere on the lane's subpath.
    """

    offset: np.ndarray
    lane: np.ndarray
    index: np.ndarray
    p: np.ndarray
    n: np.ndarray
    eps: np.ndarray
    wo: np.ndarray
    beta: np.ndarray
    fwd: np.ndarray
    rev: np.ndarray
    g_prev: np.ndarray
    delta: np.ndarray
    kind: np.ndarray
    material: np.ndarray
    entity: np.ndarray
    q: np.ndarray
    infinite: np.ndarray
    u: np.ndarray
    terminated: np.ndarray

    @property
    def length(self) -> np.ndarray:
        """Vertices per lane."""
        return np.diff(self.offset)

    @property
    def count(self) -> int:
        """Vertices in all."""
        return int(self.offset[-1])


@dataclass
class LensHits:
    """Light-walk rays that pass through a thin lens: the lens would be vertex ``index`` of the subpath.

    ``point`` (3, H) float64 on the lens; ``direction`` (3, H) of the ray;
    ``beta`` (C, H) throughput arriving; ``pdf`` (H,) solid-angle density of
    the direction (with q), or the disk density after an infinite light;
    ``distance`` (H,) from the previous vertex (unused after infinite ones).
    """

    lane: np.ndarray
    index: np.ndarray
    point: np.ndarray
    direction: np.ndarray
    beta: np.ndarray
    pdf: np.ndarray
    distance: np.ndarray

    @classmethod
    def concatenate(cls, parts: list[dict], channels: int) -> "LensHits":
        if not parts:
            return cls(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((3, 0)), np.zeros((3, 0), np.float32),
                       np.zeros((channels, 0)), np.zeros(0), np.zeros(0))
        return cls(**{name: np.concatenate([part[name] for part in parts], axis=-1) for name in parts[0]})


class _Vertices:
    """Vertices collected depth by depth (records of the lanes that have them), flattened at the end."""

    def __init__(self) -> None:
        self.records: list[dict[str, np.ndarray]] = []

    def add(self, **arrays: np.ndarray) -> dict[str, np.ndarray]:
        self.records.append(arrays)
        return arrays

    def flatten(self, lanes: int, terminated: np.ndarray) -> Subpaths:
        # Records hold vertices depth by depth; a stable sort by lane puts them lane by lane, in depth order.
        lane = np.concatenate([record["lane"] for record in self.records])
        order = np.argsort(lane, kind="stable")
        offset = np.concatenate([[0], np.cumsum(np.bincount(lane, minlength=lanes))]).astype(np.int64)
        fields = {name: np.concatenate([record[name] for record in self.records], axis=-1).take(order, axis=-1)
                  for name in FIELDS}
        return Subpaths(offset=offset, terminated=terminated, **fields)


@dataclass
class _Walk:
    """The live lanes of a random walk and what their next vertex needs."""

    lanes: np.ndarray
    origin: np.ndarray         # (3, N) float32: the previous vertex, where the ray starts
    tmin: np.ndarray           # (N,) float32: how far along the ray it starts
    direction: np.ndarray      # (3, N) float32 unit
    beta: np.ndarray           # (C, N) throughput carried to the next vertex
    pdf: np.ndarray            # (N,) solid-angle density of the direction (with q), or a disk density
    prev_n: np.ndarray         # (3, N) normal of the previous vertex (zero: no cosine there)
    prev_infinite: np.ndarray  # (N,) the previous vertex is at infinity
    prev_record: dict | None   # the record holding the previous vertex (to set its rev)

    def keep(self, indices: np.ndarray) -> None:
        for name in ("lanes", "tmin", "pdf", "prev_infinite"):
            setattr(self, name, getattr(self, name).take(indices))
        for name in ("origin", "direction", "beta", "prev_n"):
            setattr(self, name, np.take(getattr(self, name), indices, axis=-1))


def _record(vertices: _Vertices, lanes, index, p, n, eps, wo, beta, fwd, g_prev, kind, material, entity, q, infinite,
            u, delta) -> dict:
    count = lanes.size
    return vertices.add(lane=lanes, index=np.full(count, index, dtype=np.int64), p=p, n=n, eps=eps, wo=wo, beta=beta,
                        fwd=fwd, rev=np.zeros(count), g_prev=g_prev, delta=delta,
                        kind=np.full(count, kind, dtype=np.int8), material=material, entity=entity, q=q,
                        infinite=infinite, u=u)


def _cos_at(normal: np.ndarray, w: np.ndarray) -> np.ndarray:
    """|cos| between unit ``w`` and normals (3, N); 1 where the normal is zero (point lights)."""
    return np.where((normal != 0).any(axis=0), np.abs(dot(normal, w)).astype(np.float64), 1.0)


def _walk(scene, vertices: _Vertices, walk: _Walk, sampler, colours, mode: str, options: dict, q_table,
          max_vertices: int, extra: int, lens_hits: list | None, escapes: bool, terminated: np.ndarray,
          counters: dict) -> int:
    """Grow subpaths from vertex 1 on: trace, record the hit, sample the BSDF, roulette.  Returns rays traced."""
    mesh, table, camera = scene.mesh, scene.materials, scene.camera
    emitter_of = scene.lights.area.emitter_of_triangle
    env_entity = scene.lights.count - 1
    rays = 0
    index = 1
    while walk.lanes.size and index < max_vertices:
        hits = scene.accel.intersect(walk.origin, walk.direction, walk.tmin, normals=False, threads=1)
        rays += walk.lanes.size
        hit = hits.prim >= 0
        if lens_hits is not None:
            t_lens, on_lens = camera.intersect_lens(walk.origin, walk.direction)
            on_lens &= (t_lens < hits.t) & (t_lens > walk.tmin)
            k = np.flatnonzero(on_lens)
            if k.size:
                d = np.take(walk.direction, k, axis=1)
                lens_hits.append(dict(
                    lane=walk.lanes.take(k), index=np.full(k.size, index, dtype=np.int64),
                    point=np.take(walk.origin, k, axis=1).astype(np.float64) + d * t_lens.take(k), direction=d,
                    beta=np.take(walk.beta, k, axis=1), pdf=walk.pdf.take(k), distance=t_lens.take(k)))
        if escapes and not hit.all():
            k = np.flatnonzero(~hit)
            count = k.size
            d = np.take(walk.direction, k, axis=1)
            _record(vertices, walk.lanes.take(k), index, np.take(walk.origin, k, axis=1), d,
                    np.zeros(count, np.float32), -d, np.take(walk.beta, k, axis=1), walk.pdf.take(k),
                    _cos_at(np.take(walk.prev_n, k, axis=1), d), LIGHT,
                    np.full(count, -1, np.int64), np.full(count, env_entity, np.int64), np.ones(count),
                    np.ones(count, bool), np.zeros((extra, count)), np.zeros(count, bool))
        prim, b1, b2, t = hits.prim, hits.u, hits.v, hits.t
        if not hit.all():
            alive = np.flatnonzero(hit)
            walk.keep(alive)
            sampler.keep(alive)
            prim, b1, b2, t = prim.take(alive), b1.take(alive), b2.take(alive), t.take(alive)
            if not walk.lanes.size:
                break
        count = walk.lanes.size
        p, normal, eps = mesh.hit_geometry(prim, b1, b2)
        cos_in = -dot(normal, walk.direction)
        dist2 = t.astype(np.float64) ** 2
        with np.errstate(divide="ignore", invalid="ignore"):
            fwd = walk.pdf * np.abs(cos_in).astype(np.float64) / np.where(walk.prev_infinite, 1.0, dist2)
            g_prev = np.where(walk.prev_infinite, 1.0, _cos_at(walk.prev_n, walk.direction) / dist2)
        material = mesh.material.take(prim).astype(np.int64)
        q = q_table.take(material)
        u = sampler.draw(BOUNCE_UNIFORMS + extra)
        record = _record(vertices, walk.lanes, index, p, normal, eps, -walk.direction, walk.beta, fwd, g_prev, SURFACE,
                         material, emitter_of.take(prim), q, np.zeros(count, bool), u[BOUNCE_UNIFORMS:],
                         table.delta.take(material))
        if index + 1 >= max_vertices:
            if max_vertices >= SAFETY_VERTICES:
                counters["truncated"] += count
            break
        surface = Surface.facing(normal, walk.direction, cos_in)
        materials = MaterialLanes(table, material, colours.take(walk.lanes), options)
        sample = materials.sample(surface, u[0:3], mode)
        # The previous vertex as the opposite walk would generate it from here (Veach 1997, eq. 10.7).
        pdf_back = np.where(sample.delta, 0.0, reverse_pdf(materials, normal, sample.wi, -walk.direction)) * q
        rev = pdf_back * g_prev
        if walk.prev_record is not None:
            prev = walk.prev_record
            prev["rev"][np.searchsorted(prev["lane"], walk.lanes)] = rev
        if sample.terminated is not None:
            terminated[walk.lanes[sample.terminated]] = True
        keep = (u[3] < q) & (sample.weight.max(axis=0) > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            walk.beta = walk.beta * (sample.weight / q)
        walk.pdf = np.where(sample.delta, 0.0, sample.pdf) * q
        walk.origin, walk.direction = p, sample.wi
        walk.tmin = leave_distance(eps, dot(normal, sample.wi))
        walk.prev_n, walk.prev_infinite, walk.prev_record = normal, np.zeros(count, bool), record
        if not keep.all():
            live = np.flatnonzero(keep)
            walk.keep(live)
            sampler.keep(live)
        index += 1
    return rays


def camera_subpaths(scene, pixels: np.ndarray, u: np.ndarray, sampler, colours, options: dict, q_table,
                    max_vertices: int, counters: dict) -> tuple[Subpaths, int]:
    """Camera subpaths through ``pixels`` (one lane each, camera uniforms ``u`` (4, N)): (subpaths, rays).

    Vertex 0 is the lens point (density 1 / lens area; a pinhole's is a delta
    and is given 1), with throughput 1: the pixel value is the average
    radiance arriving through the pixel (We cos / (p_pos p_dir) = 1).
    """
    camera = scene.camera
    count = pixels.size
    lanes = np.arange(count)
    origin, direction = camera.generate_rays(pixels, u[0:2], u[2:4])
    origin = np.ascontiguousarray(origin, dtype=np.float32)
    axis = np.repeat(camera.forward.astype(np.float32)[:, None], count, axis=1)
    vertices = _Vertices()
    record = _record(vertices, lanes, 0, origin, axis, np.zeros(count, np.float32), np.zeros((3, count), np.float32),
                     np.ones((colours.channels, count)), np.full(count, 1.0 / camera.lens_area), np.zeros(count),
                     CAMERA,
                     np.full(count, -1, np.int64), np.full(count, -1, np.int64), np.ones(count),
                     np.zeros(count, bool), np.zeros((CAMERA_UNIFORMS, count)), np.zeros(count, bool))
    walk = _Walk(lanes, origin, np.zeros(count, np.float32), direction, np.ones((colours.channels, count)),
                 camera.pdf_direction(direction, origin), axis, np.zeros(count, bool), record)
    terminated = np.zeros(count, bool)
    rays = _walk(scene, vertices, walk, sampler, colours, "radiance", options, q_table, max_vertices,
                 CAMERA_UNIFORMS, None, scene.lights.environment is not None, terminated, counters)
    return vertices.flatten(count, terminated), rays


def light_subpaths(scene, u: np.ndarray, sampler, colours, options: dict, q_table, max_vertices: int,
                   lens: bool, counters: dict) -> tuple[Subpaths, LensHits, int]:
    """Light subpaths, one per lane, from uniforms ``u`` (5 + 2, N): (subpaths, lens hits, rays traced).

    Vertex 0 is on a light chosen by power, with density ``origin_pdf`` (see
    :meth:`pathspace.lights.LightSet.origin_pdf`) and throughput 1 / (pmf x
    positional density) -- what a connection from it to the camera needs;
    the ray leaving it carries Le |cos| / (pmf p_pos p_dir).  ``lens``: look
    for rays through a thin lens.
    """
    lights = scene.lights
    count = u.shape[1]
    lanes = np.arange(count)
    e = lights.sample_emission(u[0:5], colours, "power")
    with np.errstate(divide="ignore", invalid="ignore"):
        beta0 = np.where(e.pdf_pos > 0, 1.0 / e.pdf_pos, 0.0)
        beta = e.value * np.where(e.pdf_dir > 0, beta0 * e.cos_light / e.pdf_dir, 0.0)
    vertices = _Vertices()
    record = _record(vertices, lanes, 0, e.point.astype(np.float32), e.normal, e.epsilon,
                     np.zeros((3, count), np.float32), np.repeat(beta0[None, :], colours.channels, axis=0),
                     lights.origin_pdf(e.entity), np.zeros(count), LIGHT, np.full(count, -1, np.int64),
                     e.entity.astype(np.int64), np.ones(count), e.infinite, u[5:5 + LIGHT_UNIFORMS],
                     np.zeros(count, bool))
    # From an infinite light the next vertex's density is the disk density, projected at the hit.
    pmf = lights.pmf("power").take(e.entity)
    with np.errstate(divide="ignore", invalid="ignore"):
        pdf = np.where(e.infinite, e.pdf_pos / pmf, e.pdf_dir)
    walk = _Walk(lanes, e.point.astype(np.float32), e.tmin, e.direction, beta, pdf, e.normal, e.infinite, record)
    terminated = np.zeros(count, bool)
    hits: list = []
    rays = _walk(scene, vertices, walk, sampler, colours, "importance", options, q_table, max_vertices,
                 LIGHT_UNIFORMS, hits if lens else None, False, terminated, counters)
    return vertices.flatten(count, terminated), LensHits.concatenate(hits, colours.channels), rays
