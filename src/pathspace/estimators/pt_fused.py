"""The fused vertex of a walk: next-event estimation, BSDF sampling and roulette in one C pass.

:meth:`PathTracer._scatter <pathspace.estimators.pt.PathTracer>` is a dozen
array operations per bounce; for the scenes and settings most renders use,
``ext/pt_vertex.c`` does all of it per lane in one pass, bit for bit as the
NumPy code does (which stays the reference, and serves every other case):

- RGB rendering;
- diffuse, mirror and smooth dielectric materials (the models of
  :mod:`pathspace.bsdfs` in :data:`MODELS`);
- light sampling "mis", "nee" or "none" (not "mixture"), with area lights
  alone, points sampled by area, where light samples are taken.

The camera and light subpaths of light tracing and BDPT take their vertices
through the same kernel (:func:`walk_vertex`; no light samples, importance
transported from the lights, and the reverse densities of the directions
sampled, :meth:`pathspace.estimators.subpaths._Growth._vertex`).

:func:`fused_vertex` and :func:`walk_vertex` say whether a scene and
settings are served, and why not.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import _native
from ..bsdfs import DIFFUSE_SAMPLING, Dielectric, Diffuse, Mirror
from ..lights import AreaLight
from ..roulette import POLICIES
from ..spectra import RGBColours, RGBMode
from ..warp import azimuth

__all__ = ["MODELS", "FusedVertex", "VertexResult", "diffuse_tables", "emitter_radiance", "fused_vertex",
           "material_rgb", "unserved", "walk_vertex"]

# The material models the kernel implements (these classes, not subclasses), by the numbers ext/pt_vertex.c
# gives their kinds.
MODELS = {model: _native.PT_VERTEX_KINDS.index(model.kind) for model in (Diffuse, Mirror, Dielectric)}
# The numbers of a path tracer's vertex, in the rows the kernel reads (PathTracer.dimensions without mixture
# sampling); the BSDF's numbers follow the light sample's, and the azimuth of a diffuse sample's direction is
# u.bsdf[2] (see Diffuse.sample).
VERTEX_LAYOUT = {"light": 3, "bsdf": 3, "roulette": 1}


@dataclass
class VertexResult:
    """What the fused vertex gives for N lanes: the light samples' unoccluded ``value`` (3, N) and whether
    each is ``useful`` (worth a shadow ray toward ``light_point``, ``light_normal``, ``light_eps`` from the
    surface's ``normal`` turned toward the arriving ray); the walk's next ``beta`` (3, N), ``alive``,
    ``origin``, ``direction``, ``pdf``, ``delta`` and ``eta_scale`` (None without throughput roulette of
    radiance); the density with which the BSDF samples the way back, light arriving along the new direction
    (``pdf_back``, for subpaths; else None); and the number of ``light_samples`` taken.  For subpaths, ``pdf``
    and ``pdf_back`` of specular samples are the MIS densities of
    :func:`~pathspace.estimators.subpaths.specular_densities`."""

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
    pdf_back: np.ndarray | None
    light_samples: int


@dataclass(frozen=True, eq=False)
class FusedVertex:
    """The tables and options ``ext/pt_vertex.c`` reads, for one scene and one walk's settings."""

    materials: tuple          # kind (M,) int8, reflectance (3, M), ior (M,), roulette albedo (M,)
    lights: tuple             # table, area, two_sided, cdf, pmf, radiance (3, E); all None without light samples
    needs_azimuth: bool       # some material is diffuse
    options: tuple            # diffuse technique, heuristic (-1: none), roulette policy, rr_depth, trapped depth,
                              # exponent, termination probability, cap
    walk: tuple = (VERTEX_LAYOUT["light"], 0, 0)  # the first row of the BSDF's numbers, importance (1) or radiance
                                                  # (0) transported, whether to give the reverse densities

    def __call__(self, arrival, lanes, u: np.ndarray) -> VertexResult:
        """The vertex of every lane of ``lanes`` at ``arrival``, from its numbers ``u`` (R, N): for a path tracer
        light (3), BSDF (3) and roulette (1), as :meth:`PathTracer.dimensions` lays them out; for a subpath, the
        BSDF's and roulette's from row ``walk[0]`` on."""
        u = np.ascontiguousarray(u, np.float64)
        if self.needs_azimuth:
            phi = azimuth(u[self.walk[0] + 2])
            cos_phi, sin_phi = np.cos(phi), np.sin(phi)
        else:
            cos_phi = sin_phi = np.zeros(u.shape[1], np.float32)
        importance = self.walk[1]
        eta_scale = lanes.eta_scale if not importance and "eta_scale" in lanes.fields else None
        rr_scale = lanes.rr_scale if importance and "rr_scale" in lanes.fields else None
        return VertexResult(*_native.pt_vertex(
            *self.materials, *self.lights, arrival.p, arrival.normal, arrival.eps, arrival.cos, arrival.direction,
            arrival.material, lanes.beta, eta_scale, rr_scale, lanes.depth, u, cos_phi, sin_phi, *self.options,
            *self.walk))


def fused_vertex(tracer, scene, mode, strategy: str, heuristic: int) -> tuple[FusedVertex | None, str]:
    """(the fused vertex, "") if ``tracer`` (a PathTracer) can take its vertices on ``scene`` in ``mode``
    through ``ext/pt_vertex.c``, with the light ``strategy`` in use and light samples weighted by
    ``heuristic`` (``pt.MIS_CODES``; -1 without light samples); else (None, why not)."""
    reason = unserved(scene, isinstance(mode, RGBMode), tracer.kernel)
    if reason:
        return None, reason
    table = scene.materials
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
    materials, needs_azimuth = _materials(table)
    options = _options(tracer.diffuse_sampling, heuristic, tracer.roulette, float(tracer.mis_beta))
    return FusedVertex(materials, light_tables, needs_azimuth, options), ""


def walk_vertex(scene, colours, roulette, options: dict, dims, transport: str, densities: bool,
                kernel: str) -> tuple[FusedVertex | None, str]:
    """(the fused vertex, "") if a subpath walk with ``kernel`` ("fused" or "numpy") can take its vertices on
    ``scene`` through ``ext/pt_vertex.c``: rendering with ``colours``, under ``roulette`` and the material
    ``options`` (``diffuse_sampling``), drawing ``dims`` (a :class:`~pathspace.estimators.walk.Dimensions` with
    the BSDF's 3 numbers and the roulette's 1 in a row), transporting ``transport`` ("radiance" from the camera,
    "importance" from the lights), with or without the reverse ``densities``; else (None, why not)."""
    reason = unserved(scene, colours is RGBColours, kernel)
    if reason:
        return None, reason
    names, sizes = list(dims.sizes), dims.sizes
    bsdf = names.index("bsdf")
    if names[bsdf + 1:bsdf + 2] != ["roulette"] or (sizes["bsdf"], sizes["roulette"]) != (3, 1):
        return None, "the vertex's numbers are laid out differently"
    bsdf_row = sum(sizes[name] for name in names[:bsdf])
    materials, needs_azimuth = _materials(scene.materials)
    walk = (bsdf_row, int(transport == "importance"), int(densities))
    return FusedVertex(materials, (None,) * 6, needs_azimuth,
                       _options(options.get("diffuse_sampling", "cosine"), -1, roulette, 2.0), walk), ""


def _materials(table) -> tuple[tuple, bool]:
    """The kernel's material tables of ``table`` (a MaterialTable: kind, reflectance (3, M), interior index and
    roulette albedo), and whether any material is diffuse."""
    kinds = np.array([MODELS[type(m)] for m in table.materials], dtype=np.int8)
    reflectance, ior = material_rgb(table)
    diffuse = bool((kinds == MODELS[Diffuse]).any())
    return (kinds, reflectance, ior, np.ascontiguousarray(table.albedo, np.float64)), diffuse


def _options(technique: str, heuristic: int, roulette, exponent: float) -> tuple:
    """The kernel's options: the diffuse ``technique``, the light samples' ``heuristic`` (-1: none), ``roulette``
    (a RussianRoulette) and the heuristic's ``exponent``."""
    depth_limit = np.iinfo(np.int32).max   # depths are int32: a later start is never reached
    return (DIFFUSE_SAMPLING.index(technique), heuristic, POLICIES.index(roulette.policy),
            min(roulette.start_depth, depth_limit), roulette.trapped_depth, exponent, float(roulette.probability),
            float(roulette.cap))


def unserved(scene, rgb: bool, kernel: str) -> str:
    """Why the fused kernels cannot take a render of ``scene`` in RGB (``rgb``) or spectrally with ``kernel``
    ("fused" or "numpy"), for what they all need: the kernel chosen, RGB, and materials of :data:`MODELS`; or ""
    if they can."""
    if kernel != "fused":
        return "kernel='numpy'"
    if not rgb:
        return "spectral rendering"
    for name, material in zip(scene.materials.names, scene.materials.materials):
        if type(material) not in MODELS:
            return f"material {name!r} is {material.kind}"
    return ""


def diffuse_tables(table, options: dict) -> tuple[np.ndarray, np.ndarray, int]:
    """What the kernels that evaluate only the diffuse model read of ``table`` (a MaterialTable of
    :data:`MODELS`): which materials are diffuse (M,) bool, the reflectances (3, M), and the index in
    DIFFUSE_SAMPLING of the technique the material ``options`` choose (``diffuse_sampling``)."""
    diffuse = np.array([type(m) is Diffuse for m in table.materials], dtype=bool)
    return diffuse, material_rgb(table)[0], DIFFUSE_SAMPLING.index(options.get("diffuse_sampling", "cosine"))


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
