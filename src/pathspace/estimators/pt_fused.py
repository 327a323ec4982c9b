"""The path tracer's fused vertex: next-event estimation, BSDF sampling and roulette in one C pass.

:meth:`PathTracer._scatter <pathspace.estimators.pt.PathTracer>` is a dozen
array operations per bounce; for the scenes and settings most renders use,
``ext/pt_vertex.c`` does all of it per lane in one pass, bit for bit as the
NumPy code does (which stays the reference, and serves every other case):

- RGB rendering;
- diffuse, mirror and smooth dielectric materials (the models of
  :mod:`pathspace.bsdfs` in :data:`MODELS`);
- light sampling "mis", "nee" or "none" (not "mixture"), with area lights
  alone, points sampled by area, where light samples are taken.

:func:`fused_vertex` says whether a scene and settings are served, and why not.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import _native
from ..bsdfs import DIFFUSE_SAMPLING, Dielectric, Diffuse, Mirror
from ..lights import AreaLight
from ..roulette import POLICIES, TRAPPED_DEPTH
from ..spectra import RGBMode
from ..warp import azimuth

__all__ = ["MODELS", "FusedVertex", "VertexResult", "emitter_radiance", "fused_vertex", "material_rgb",
           "unserved_material"]

# The material models the kernel implements (these classes, not subclasses), by the numbers ext/pt_vertex.c
# gives their kinds.
MODELS = {model: _native.PT_VERTEX_KINDS.index(model.kind) for model in (Diffuse, Mirror, Dielectric)}
# The numbers of a vertex, in the rows the kernel reads (PathTracer.dimensions without mixture sampling); the
# azimuth of a diffuse sample's direction is u.bsdf[2] (see Diffuse.sample).
VERTEX_LAYOUT = {"light": 3, "bsdf": 3, "roulette": 1}
AZIMUTH_ROW = VERTEX_LAYOUT["light"] + 2


@dataclass
class VertexResult:
    """What the fused vertex gives for N lanes: the light samples' unoccluded ``value`` (3, N) and whether
    each is ``useful`` (worth a shadow ray toward ``light_point``, ``light_normal``, ``light_eps`` from the
    surface's ``normal`` turned toward the arriving ray); the walk's next ``beta`` (3, N), ``alive``,
    ``origin``, ``direction``, ``pdf``, ``delta`` and ``eta_scale`` (None without throughput roulette); and
    the number of ``light_samples`` taken."""

    value: np.ndarray
    useful: np.ndarray
    light_point: np.ndarray
    light_normal: np.ndarray
    light_eps: np.ndarray
    normal: np.ndarray
    beta: np.ndarray
    alive: np.ndarray
    origin: np.ndarray
    direction: np.ndarray
    pdf: np.ndarray
    delta: np.ndarray
    eta_scale: np.ndarray | None
    light_samples: int


@dataclass(frozen=True, eq=False)
class FusedVertex:
    """The tables and options ``ext/pt_vertex.c`` reads, for one scene and one path tracer's settings."""

    materials: tuple          # kind (M,) int8, reflectance (3, M), ior (M,), roulette albedo (M,)
    lights: tuple             # table, area, two_sided, cdf, pmf, radiance (3, E); all None without light samples
    needs_azimuth: bool       # some material is diffuse
    options: tuple            # diffuse technique, heuristic (-1: none), roulette policy, rr_depth, trapped depth,
                              # exponent, termination probability, cap

    def __call__(self, arrival, lanes, u: np.ndarray) -> VertexResult:
        """The vertex of every lane of ``lanes`` at ``arrival``, from its numbers ``u`` (7, N): light (3),
        BSDF (3) and roulette (1), as :meth:`PathTracer.dimensions` lays them out."""
        u = np.ascontiguousarray(u, np.float64)
        if self.needs_azimuth:
            phi = azimuth(u[AZIMUTH_ROW])
            cos_phi, sin_phi = np.cos(phi), np.sin(phi)
        else:
            cos_phi = sin_phi = np.zeros(u.shape[1], np.float32)
        eta_scale = lanes.eta_scale if "eta_scale" in lanes.fields else None
        return VertexResult(*_native.pt_vertex(
            *self.materials, *self.lights, arrival.p, arrival.normal, arrival.eps, arrival.cos, arrival.direction,
            arrival.material, lanes.beta, eta_scale, lanes.depth, u, cos_phi, sin_phi, *self.options))


def fused_vertex(tracer, scene, mode, strategy: str, heuristic: int) -> tuple[FusedVertex | None, str]:
    """(the fused vertex, "") if ``tracer`` (a PathTracer) can take its vertices on ``scene`` in ``mode``
    through ``ext/pt_vertex.c``, with the light ``strategy`` in use and light samples weighted by
    ``heuristic`` (``pt.MIS_CODES``; -1 without light samples); else (None, why not)."""
    if tracer.kernel != "fused":
        return None, "kernel='numpy'"
    if not isinstance(mode, RGBMode):
        return None, "spectral rendering"
    table = scene.materials
    reason = unserved_material(table)
    if reason:
        return None, reason
    if strategy == "mixture":
        return None, "light_sampling='mixture'"
    if tracer.dimensions(mode)[1].sizes != VERTEX_LAYOUT:
        return None, "the vertex's numbers are laid out differently"
    lights = scene.lights
    light_tables = (None,) * 6
    if strategy in ("mis", "nee"):
        if lights.models != [AreaLight]:
            return None, "lights other than area lights"
        if tracer.light_measure != "area":
            return None, f"light_measure={tracer.light_measure!r}"
        area = lights.area
        light_tables = (area.table, area.area, area.two_sided, np.ascontiguousarray(lights.cdf(tracer.light_selection)),
                        np.ascontiguousarray(lights.pmf(tracer.light_selection)), emitter_radiance(lights))
    kinds = np.array([MODELS[type(m)] for m in table.materials], dtype=np.int8)
    reflectance, ior = material_rgb(table)
    roulette = tracer.roulette
    depth_limit = np.iinfo(np.int32).max   # depths are int32: a later start is never reached
    options = (DIFFUSE_SAMPLING.index(tracer.diffuse_sampling), heuristic, POLICIES.index(roulette.policy),
               min(roulette.start_depth, depth_limit), TRAPPED_DEPTH, float(tracer.mis_beta),
               float(roulette.probability), float(roulette.cap))
    materials = (kinds, reflectance, ior, np.ascontiguousarray(table.albedo, np.float64))
    return FusedVertex(materials, light_tables, bool((kinds == MODELS[Diffuse]).any()), options), ""


def unserved_material(table) -> str:
    """Why the fused kernels cannot render the materials of ``table`` (a MaterialTable), or "" if they can."""
    for name, material in zip(table.names, table.materials):
        if type(material) not in MODELS:
            return f"material {name!r} is {material.kind}"
    return ""


def material_rgb(table) -> tuple[np.ndarray, np.ndarray]:
    """(reflectance (3, M), interior index (M,)) of the materials of ``table``, the values MaterialLanes gathers
    in RGB (reflectance 0 for dielectrics, index 1 for the others)."""
    reflectance, ior = np.zeros((3, len(table))), np.ones(len(table))
    for m, material in enumerate(table.materials):
        tables, local = table.tables[table.kind_of[m]], table.local_id[m]
        if type(material) is Dielectric:
            ior[m] = tables["ior_reference"][local]
        else:
            reflectance[:, m] = tables["reflectance"].rgb[:, local]
    return reflectance, ior


def emitter_radiance(lights) -> np.ndarray:
    """RGB radiance (3, E) of every emitting triangle of ``lights`` (a LightSet).  Area lights are the first
    entities of a LightSet, so emitting triangle e is entity e."""
    area = lights.area
    return np.ascontiguousarray(area.radiance.rgb.take(area.light_of, axis=1))
