"""Explicit light paths x_0 .. x_k, their contribution f(x) and the densities of generating each vertex.

Path-space Metropolis light transport (Veach & Guibas 1997; Veach 1997,
ch. 11) keeps a chain's state as the path itself.  A :class:`Paths` holds
one path per lane, vertex 0 on a light (an area emitter) and vertex k at the
camera (a pinhole), padded to a common number of vertex slots.

:func:`evaluate` computes, per path, the measurement contribution in the
film's units (Veach 1997, eq. 8.7, with the camera's importance written so
that f / p is a path-tracing sample of a uniform film position)

    f(x) = Le(x_0 -> x_1) prod_{i=1}^{k-1} f_s(x_i) |cos_i| prod_{e=0}^{k-1} |cos_e| / d_e^2 p_cam(x_k -> x_{k-1}),

where f_s(x_i) |cos_i| is the BSDF at x_i times the cosine toward x_{i-1},
|cos_e| / d_e^2 the cosine at x_e toward x_{e+1} over the squared length of
segment e, and p_cam the camera's solid-angle density of directions for a
uniform film position; and the area densities with which each vertex is
generated from its neighbours (Veach 1997, sec. 10.2):

``fwd[i]``  from x_{i-1} (a walk from the light): fwd[0] the light's point density (with the
            light-choice pmf), fwd[1] the emission's direction density, then BSDF sampling;
``rev[i]``  from x_{i+1} (a walk from the camera): rev[k-1] the camera's, then BSDF sampling.

Specular (delta) vertices use the convention of Veach (1997, sec. 11.5): the
Dirac deltas of f and of the densities cancel, so a specular vertex's
"BSDF" is its lobe's weight times the lobe's probability and its "density"
is the lobe's probability (as :meth:`pathspace.bsdfs.MaterialLanes.sample`
reports them); ratios of f and of densities of paths with the same specular
vertices are then exact.  The deltas cancel only over one measure: f's and
``rev``'s are over the solid angle of the direction toward the light (the
one a walk from the camera samples), while a walk from the light samples
the direction toward the camera.  A reflection maps the two directions with
Jacobian 1; a refraction, by Snell's law (eta_i^2 cos_i dw_i =
eta_t^2 cos_t dw_t; Veach 1997, sec. 5.2), with dw_prev / dw_next =
cos_next / (eta^2 cos_prev), eta = eta_prev / eta_next, so ``g_fwd`` (and
with it ``fwd``) at the vertex after a refraction carries that factor.
Edges are assumed unoccluded: whoever builds a path traces or tests every
segment it makes.

In spectral renders (:class:`Space` with a spectral mode) a path's
wavelengths are drawn from its ``wavelength_number``; f is evaluated at them
(a dispersive interface keeps only the hero wavelength) and turned into XYZ
film values, so f / p is still a sample of the film.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import _native
from ..bsdfs import MaterialLanes, Surface
from ..spectra import RGBColours, RGBMode
from ..vecmath import dot
from .wavefront import Lanes

__all__ = ["Paths", "PathValues", "Space", "evaluate", "delta_lobe", "OPTIONS"]

# BSDF options of the paths' materials (cosine-weighted diffuse sampling).
OPTIONS = {"diffuse_sampling": "cosine"}
# Two directions are the same lobe's when their cosine exceeds this (positions are float32).
SAME_DIRECTION = 1.0 - 1e-5
_LOBE_NUMBERS = (0.0, 1.0 - 2.0 ** -20)   # the first BSDF number picking the first or the last lobe


@dataclass
class Space:
    """What paths live in: the ``scene`` and the colour ``mode`` (RGB, or spectral with the path's wavelengths
    drawn from one number per path, :attr:`Paths.wavelength_number`).  With ``specular_only``, paths without
    a specular vertex have f = 0: they are left to another estimator (a partition of path space)."""

    scene: object
    mode: object = field(default_factory=RGBMode)
    specular_only: bool = False

    @property
    def spectral(self) -> bool:
        """Whether paths carry wavelengths."""
        return self.mode.name != "rgb"

    def colours(self, numbers: np.ndarray):
        """(colour state (a :class:`Lanes` of the mode's path fields, or None in RGB), colour model) of paths with
        wavelength ``numbers`` (N,)."""
        if not self.spectral:
            return None, RGBColours
        state = Lanes(self.mode.path_fields, **self.mode.start(numbers[None, :]))
        return state, self.mode.colours(state)


@dataclass
class Paths:
    """One path per lane: ``k`` (N,) segments; per vertex slot (N, K): ``p`` and ``n`` (3, N, K) float32 position
    and geometric normal (the light's normal at vertex 0, the camera axis at vertex k), ``eps`` ray-offset
    bound, ``material`` (-1 at the light and camera vertices) and ``entity`` (the light entity of vertex 0 and
    of surface vertices on emitters, else -1); ``wavelength_number`` (N,): the uniform number that draws the
    path's wavelengths in spectral renders (part of the state; unused in RGB)."""

    k: np.ndarray
    p: np.ndarray
    n: np.ndarray
    eps: np.ndarray
    material: np.ndarray
    entity: np.ndarray
    wavelength_number: np.ndarray

    FIELDS = ("p", "n", "eps", "material", "entity")   # per vertex slot

    @classmethod
    def empty(cls, count: int, slots: int) -> "Paths":
        """``count`` paths of no segments with ``slots`` vertex slots each."""
        return cls(np.zeros(count, np.int64), np.zeros((3, count, slots), np.float32),
                   np.zeros((3, count, slots), np.float32), np.zeros((count, slots), np.float32),
                   np.full((count, slots), -1, np.int64), np.full((count, slots), -1, np.int64), np.zeros(count))

    @property
    def count(self) -> int:
        """Number of paths."""
        return int(self.k.size)

    @property
    def slots(self) -> int:
        """Vertex slots per path."""
        return int(self.material.shape[1])

    def vertex(self, lanes: np.ndarray, index: np.ndarray) -> dict[str, np.ndarray]:
        """Fields of vertex ``index`` of paths ``lanes`` (both (n,)): ``p``, ``n`` (3, n), ``eps``, ``material``,
        ``entity`` (n,)."""
        return {name: getattr(self, name)[..., lanes, index] for name in self.FIELDS}

    def put(self, lanes: np.ndarray, index: np.ndarray, vertex: dict[str, np.ndarray]) -> None:
        """Write ``vertex`` (fields as :meth:`vertex` returns them) into slot ``index`` of paths ``lanes``."""
        for name in self.FIELDS:
            getattr(self, name)[..., lanes, index] = vertex[name]

    def take(self, lanes: np.ndarray, slots: int | None = None) -> "Paths":
        """The paths ``lanes``, with their first ``slots`` vertex slots (default: all)."""
        return Paths(self.k.take(lanes), *(np.take(getattr(self, name)[..., :slots], lanes, axis=-2)
                                           for name in self.FIELDS), self.wavelength_number.take(lanes))

    def assign(self, lanes: np.ndarray, other: "Paths") -> None:
        """Paths ``lanes`` become ``other``'s (one each; ``other`` may have fewer vertex slots)."""
        self.k[lanes] = other.k
        self.wavelength_number[lanes] = other.wavelength_number
        for name in self.FIELDS:
            getattr(self, name)[..., lanes, :other.slots] = getattr(other, name)


@dataclass
class PathValues:
    """What :func:`evaluate` finds: ``f`` (C, N) film contribution (0 for impossible paths), ``raster`` (2, N)
    film position, ``pixel`` (N,), per vertex slot (N, K) ``fwd`` and ``rev`` area densities (see the module
    docstring), ``delta`` (specular vertices), ``g_fwd`` |cos_i| / d^2 of segment i-1 (times Snell's Jacobian of
    a refraction at x_{i-1}, see the module docstring) and ``g_rev`` |cos_i| / d^2 of segment i: what turns a
    solid-angle density at the neighbour into an area density at x_i, in f's measure."""

    f: np.ndarray
    raster: np.ndarray
    pixel: np.ndarray
    fwd: np.ndarray
    rev: np.ndarray
    delta: np.ndarray
    g_fwd: np.ndarray
    g_rev: np.ndarray

    PER_LANE = ("f", "raster", "pixel")                         # lanes on the last axis
    PER_VERTEX = ("fwd", "rev", "delta", "g_fwd", "g_rev")      # (N, K)

    def take(self, lanes: np.ndarray, slots: int | None = None) -> "PathValues":
        """The values of paths ``lanes``, with their first ``slots`` vertex slots (default: all)."""
        return PathValues(**{name: np.take(getattr(self, name), lanes, axis=-1) for name in self.PER_LANE},
                          **{name: getattr(self, name)[lanes, :slots] for name in self.PER_VERTEX})

    def assign(self, lanes: np.ndarray, other: "PathValues") -> None:
        """Paths ``lanes`` take ``other``'s values (one each; ``other`` may have fewer vertex slots)."""
        for name in self.PER_LANE:
            getattr(self, name)[..., lanes] = getattr(other, name)
        width = other.fwd.shape[1]
        for name in self.PER_VERTEX:
            getattr(self, name)[lanes, :width] = getattr(other, name)


def delta_lobe(materials: MaterialLanes, surface: Surface, toward: np.ndarray, mode: str):
    """(f |cos| (C, n), probability (n,), eta (n,), terminated (n,)) of the delta lobe of each lane's specular
    material that scatters light seen as ``surface`` toward unit ``toward`` (3, n): the lobe's weight times its
    probability, its probability (zero where no lobe goes there), the relative index eta_t / eta_i it crosses
    toward ``toward`` (1 where it reflects), and whether it kept only the hero wavelength (dispersion)."""
    count = toward.shape[1]
    f_cos, probability, eta = np.zeros((materials.channels, count)), np.zeros(count), np.ones(count)
    terminated = np.zeros(count, bool)
    for first in _LOBE_NUMBERS:
        u = np.vstack((np.full(count, first), np.full((2, count), 0.5)))
        sample = materials.sample(surface, u, mode)
        match = (dot(sample.wi.astype(np.float64), toward) > SAME_DIRECTION) & (sample.pdf > 0)
        f_cos = np.where(match, sample.weight * sample.pdf, f_cos)
        probability = np.where(match, sample.pdf, probability)
        if sample.eta is not None:
            eta = np.where(match, sample.eta, eta)
        if sample.terminated is not None:
            terminated |= match & sample.terminated
    return f_cos, probability, eta, terminated


def _scattering(scene, colours, material: np.ndarray, n: np.ndarray, to_prev: np.ndarray, to_next: np.ndarray):
    """At surface vertices with ``material`` and normals ``n`` (3, n) and ``colours``, neighbours along unit
    ``to_prev`` (toward the light end) and ``to_next`` (toward the camera): (f_s |cos toward prev| (C, n) for
    light arriving from prev, density of sampling ``to_prev`` from the camera side, density of sampling
    ``to_next`` from the light side, the Jacobian d w_prev / d w_next that takes a delta lobe's density from
    the light side to f's measure (1 but for refractions; see the module docstring), specular, kept only the
    hero wavelength)."""
    table = scene.materials
    materials = MaterialLanes(table, material, colours, OPTIONS)
    delta = table.delta.take(material)
    terminated = np.zeros(material.size, bool)
    snell = np.ones(material.size)
    from_camera = Surface.facing(n, -to_next)   # a walk from the camera arrives from the next vertex
    from_light = Surface.facing(n, -to_prev)    # a walk from the light arrives from the previous one
    f_cos, pdf_prev = materials.eval(from_camera, to_prev.astype(np.float32))
    _, pdf_next = materials.eval(from_light, to_next.astype(np.float32))
    d, specular = materials.part(specular=True)
    if d.size:
        prev, following = np.take(to_prev, d, axis=1), np.take(to_next, d, axis=1)
        lobe_f, lobe_prev, eta, terminated[d] = delta_lobe(specular, from_camera.take(d), prev, "radiance")
        _, lobe_next, _, _ = delta_lobe(specular, from_light.take(d), following, "importance")
        f_cos[:, d], pdf_prev[d], pdf_next[d] = lobe_f, lobe_prev, lobe_next
        normal = np.take(n, d, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            jacobian = np.abs(dot(normal, following)) / (eta * eta * np.abs(dot(normal, prev)))
        snell[d] = np.where(eta == 1.0, 1.0, np.where(np.isfinite(jacobian), jacobian, 0.0))
    return f_cos, pdf_prev, pdf_next, snell, delta, terminated


def evaluate(space: Space, paths: Paths) -> PathValues:
    """f(x) as film values, the film position and the vertex densities of every path (see the module
    docstring); f = 0 for paths ``space`` leaves out."""
    scene = space.scene
    state, colours = space.colours(paths.wavelength_number)
    count, slots = paths.material.shape
    lanes = np.arange(count)
    k = paths.k
    # Segment i, x_i -> x_{i+1}: its unit direction w[:, :, i], g_rev[:, i] = |cos| at x_i / d^2 and
    # g_fwd[:, i + 1] = |cos| at x_{i+1} / d^2; segments = the product of the g_rev (ext/paths.c).
    w, g_fwd, g_rev, segments = _native.path_geometry(np.ascontiguousarray(paths.p), np.ascontiguousarray(paths.n),
                                                      np.ascontiguousarray(k, dtype=np.int64))
    fwd, rev = np.zeros((count, slots)), np.zeros((count, slots))
    delta = np.zeros((count, slots), bool)
    f = np.ones((colours.channels, count))
    # The light: x_0's emission toward x_1, its point density and the direction's.
    entity = paths.entity[:, 0]
    w0 = np.ascontiguousarray(w[:, :, 0])
    lit = (entity >= 0) & (k >= 1)
    safe_entity = np.where(lit, entity, 0)
    f *= np.where(lit, scene.lights.le(safe_entity, paths.n[:, :, 0], w0.astype(np.float32), colours), 0.0)
    origin, pdf_dir = scene.lights.pdf_le(safe_entity, paths.n[:, :, 0], w0.astype(np.float32))
    fwd[:, 0] = np.where(lit, origin, 0.0)
    fwd[:, 1] = np.where(lit, pdf_dir * g_fwd[:, 1], 0.0)
    # Surface vertices x_1 .. x_{k-1}.
    row, col = np.nonzero((np.arange(slots)[None, :] >= 1) & (np.arange(slots)[None, :] < k[:, None]))
    terminated = np.zeros(count, bool)
    if row.size:
        f_cos, pdf_prev, pdf_next, snell, specular, dispersed = _scattering(
            scene, colours.take(row), paths.material[row, col], paths.n[:, row, col], -w[:, row, col - 1],
            w[:, row, col])
        terminated[row[dispersed]] = True
        starts = np.flatnonzero(np.diff(row, prepend=-1))    # row ascends (np.nonzero): each path's vertices
        f[:, row.take(starts)] *= np.multiply.reduceat(f_cos, starts, axis=1)
        rev[row, col - 1] = pdf_prev * g_rev[row, col - 1]
        nxt = col + 1 < k[row]
        g_fwd[row[nxt], col[nxt] + 1] *= snell[nxt]
        fwd[row[nxt], col[nxt] + 1] = pdf_next[nxt] * g_fwd[row[nxt], col[nxt] + 1]
        delta[row, col] = specular
    # Segments and the camera.
    camera = scene.camera
    last = np.maximum(k - 1, 0)
    toward_path = -w[:, lanes, last]                         # from the camera to x_{k-1}
    pdf_camera = camera.pdf_direction(toward_path.astype(np.float32))
    rev[lanes, last] = pdf_camera * g_rev[lanes, last]
    f *= segments * pdf_camera
    raster, inside = camera.raster(paths.p[:, lanes, last])
    kept = inside & (k >= 1) & np.isfinite(f).all(axis=0)
    if space.specular_only:
        kept &= delta.any(axis=1)
    f = np.where(kept, f, 0.0)
    if state is not None:     # spectral: the wavelengths' radiance as XYZ film values
        if terminated.any():
            space.mode.terminate_secondary(state, terminated)
        f = space.mode.to_film(f, state, lanes)
    return PathValues(f, raster, camera.pixel_of(raster), fwd, rev, delta, g_fwd, g_rev)
