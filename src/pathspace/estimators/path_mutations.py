"""Veach's mutations of explicit paths, with their exact transition densities (Veach & Guibas 1997, sec. 5).

Each mutation proposes y from x for a wavefront of chains and returns the
ratio T(y -> x) / T(x -> y) of its transition densities, so that a chain
accepts with a = min(1, c(f(y)) T(y -> x) / (c(f(x)) T(x -> y))) (Veach 1997,
eq. 11.3).  Densities are with respect to the area-product measure of the
vertices a mutation regenerates, in the specular convention of
:mod:`pathspace.estimators.paths`.

Bidirectional mutation (Veach 1997, sec. 11.4.2)
------------------------------------------------
Delete the k_d segments between vertices x_l and x_m (m = l + k_d; l = -1
deletes the light vertex; the pinhole camera vertex x_k is always kept),
chosen with probability p_d(k_d | k) / (k - k_d + 2): short deletions are
likely (p_d ~ 1/4, 1/2, then 2^-k_d for 1, 2, more segments, over
1 .. k + 1).  Then add k_a segments, p_a(k_a | k_d) ~ 2^-|k_a - k_d| for
|k_a - k_d| <= 2: k_a - 1 new vertices, j of them by a walk from x_l (a fresh
light sample when l = -1) and the rest by a walk from x_m (a uniform film
position when x_m is the camera), j uniform in 0 .. k_a - 1, joined by a
shadow ray.  Since any j could have made y,

    T(x -> y) = p_d p_a (1 / k_a) sum_j prod_{i in light walk} fwd_i(y) prod_{i in camera walk} rev_i(y),

with splits whose joining segment touches a specular vertex left out
(:func:`split_densities`); T(y -> x) is the same for deleting y's new
vertices and regenerating x's.  Deleting everything (l = -1, m = k) is an
independent sample of a new path.  The bootstrap's independent samples
(:func:`fresh_paths`) join one light and one camera walk in all L + 1 ways
instead, as BDPT does, with the same densities summed over the splits.

Perturbations (Veach 1997, sec. 11.4.3 and 11.4.4)
---------------------------------------------------
*Lens perturbation*: for paths ... x_j S* E with x_j (and x_{j-1}) not
specular, move the film position by an offset of radius r2 exp(-ln(r2 / r1) u)
(density ~ 1 / r between r1 and r2) at a uniform angle, follow the path's
specular lobes from the camera to a new x_j, and join it to x_{j-1}
(x_j = x_0: the walk must reach a light).  *Caustic perturbation*: for
paths x_j S* x_{k-1} E with x_j and x_{k-1} not specular, turn the direction
leaving x_j by an angle theta2 exp(-ln(theta2 / theta1) u) about a uniform
axis, follow the specular lobes to a new x_{k-1}, and join it to the camera.
*Multi-chain perturbation*: for paths ... x_i S+ x_j S* E, where the lens
perturbation cannot join x_j to a specular x_{j-1}, perturb the film
position as the lens perturbation does to a new x_j, then turn the direction
leaving it toward the light as the caustic perturbation does (from the old
x_j -> x_{j-1}) and follow the second specular chain to a new x_i, joined to
x_{i-1} (or a light, if x_i = x_0): a caustic seen through glass.  The
offsets are symmetric, so T(y -> x) / T(x -> y) is the ratio of the
Jacobians: the area densities of the regenerated vertices given the film
position (lens, multi-chain) and direction (caustic, multi-chain), x's
over y's.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import _native
from ..vecmath import orthonormal_basis
from .path_walks import (Uniforms, bsdf_direction, camera_direction, emission_direction, film_positions, light_points,
                         lobe_numbers, unit, walk)
from .paths import Paths, PathValues, Space, evaluate
from .primary import SmallStep
from .visibility import segment_blocked

__all__ = ["ADD_SPREAD", "Lengths", "Proposed", "split_densities", "bidirectional", "lens", "lens_to", "caustic",
           "caustic_toward", "multichain", "multichain_to", "perturbable", "fresh_paths", "FreshPaths"]

ADD_SPREAD = 2   # k_a differs from k_d by at most this
WAVELENGTH_STEP = SmallStep("exponential", 1.0 / 64.0)   # how bidirectional mutations move the wavelengths


@dataclass
class Proposed:
    """Proposals y of a mutation for its chains: the paths, what :func:`evaluate` found for them, and
    T(y -> x) / T(x -> y) (0 where no proposal was made; y's ``k`` is then 0 and f(y) = 0)."""

    paths: Paths
    values: PathValues
    ratio: np.ndarray


def _deletion_weight(segments: int) -> float:
    return {1: 0.25, 2: 0.5}.get(segments, 2.0 ** -segments)


@dataclass
class Lengths:
    """Veach's deletion and addition probabilities for paths of ``min_length`` .. ``max_depth`` segments."""

    max_depth: int
    min_length: int
    delete: np.ndarray = field(init=False, repr=False)   # [k, k_d]: p_d(k_d | k) over k_d = 1 .. k + 1
    add: np.ndarray = field(init=False, repr=False)      # [k_d, k_a]: p_a(k_a | k_d)

    def __post_init__(self) -> None:
        top = self.max_depth + 2
        self.delete = np.zeros((top, top))
        for k in range(1, self.max_depth + 1):
            weights = np.array([0.0] + [_deletion_weight(kd) for kd in range(1, k + 2)])
            self.delete[k, :k + 2] = weights / weights.sum()
        self.add = np.zeros((top, top + ADD_SPREAD))
        for kd in range(1, top):
            ka = np.arange(max(1, kd - ADD_SPREAD), kd + ADD_SPREAD + 1)
            weights = 2.0 ** -np.abs(ka - kd)
            self.add[kd, ka] = weights / weights.sum()

    @staticmethod
    def _pick(table: np.ndarray, rows: np.ndarray, u: np.ndarray) -> np.ndarray:
        cdf = np.cumsum(table[rows], axis=1)
        return np.minimum((cdf < u[:, None] * cdf[:, -1:]).sum(axis=1), table.shape[1] - 1)

    def pick_deletion(self, k: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Segments k_d to delete from paths of ``k`` segments."""
        return self._pick(self.delete, k, u)

    def pick_addition(self, kd: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Segments k_a to add after deleting ``kd``."""
        return self._pick(self.add, kd, u)

    def p_deletion(self, k: np.ndarray, kd: np.ndarray) -> np.ndarray:
        """Probability of deleting one given run of ``kd`` segments from paths of ``k`` segments."""
        return self.delete[k, kd] / (k - kd + 2)

    def p_addition(self, kd: np.ndarray, ka: np.ndarray) -> np.ndarray:
        """Probability of adding ``ka`` segments after deleting ``kd``."""
        return self.add[np.minimum(kd, self.add.shape[0] - 1), np.minimum(ka, self.add.shape[1] - 1)]


def split_densities(values: PathValues, first: np.ndarray, count: np.ndarray) -> np.ndarray:
    """sum_j p_j over the count + 1 splits j of vertices ``first`` .. ``first + count - 1`` of each path, p_j the
    density of making them by j steps of a walk from vertex ``first - 1`` and ``count - j`` steps of a walk from
    vertex ``first + count``, joined between them; splits whose join touches a specular vertex have density 0.
    One C pass over the paths (``ext/paths.c``)."""
    fwd, rev, delta = (np.ascontiguousarray(a) for a in (values.fwd, values.rev, values.delta))
    return _native.split_densities(fwd, rev, delta, np.ascontiguousarray(first, dtype=np.int64),
                                   np.ascontiguousarray(count, dtype=np.int64))


def _regenerate(space: Space, y: Paths, lanes: np.ndarray, light_end: np.ndarray, light_steps: np.ndarray,
                camera_end: np.ndarray, camera_steps: np.ndarray, uniforms: Uniforms) -> np.ndarray:
    """Fill the gap of paths ``lanes`` of ``y`` between slot ``light_end`` (-1: a fresh light vertex is made) and
    slot ``camera_end``: ``light_steps`` vertices by a walk from the light side, ``camera_steps`` from the camera
    side (all (n,)), joined by a shadow ray.  Returns whether each succeeded."""
    scene = space.scene
    _, colours = space.colours(y.wavelength_number.take(lanes))
    ok = np.ones(lanes.size, bool)
    # The walk from the light side.
    go = np.flatnonzero(light_steps > 0)
    if go.size:
        end = light_end.take(go)
        start = y.vertex(lanes.take(go), np.maximum(end, 0))
        direction = np.zeros((3, go.size), np.float32)
        u = uniforms(5 * go.size).reshape(5, go.size)
        fresh, at_light, surface = np.flatnonzero(end < 0), np.flatnonzero(end == 0), np.flatnonzero(end > 0)
        if fresh.size:
            vertex, direction[:, fresh] = light_points(scene, u[:, fresh])
            y.put(lanes.take(go.take(fresh)), np.zeros(fresh.size, np.int64), vertex)
            for name, value in vertex.items():
                start[name][..., fresh] = value
        if at_light.size:
            direction[:, at_light] = emission_direction(scene, _part(start, at_light), u[:2, at_light])
        if surface.size:
            rows = lanes.take(go.take(surface))
            arriving = unit(y.p[:, rows, end[surface]] - y.p[:, rows, end[surface] - 1])
            direction[:, surface] = bsdf_direction(scene, _part(start, surface), arriving, "importance",
                                                   u[:3, surface], colours.take(go.take(surface)))
        steps = light_steps.take(go) - (end < 0)
        made, reached = walk(scene, start, direction, steps, "importance", uniforms, colours.take(go))
        ok[go[reached < steps]] = False
        first = np.maximum(end, -1) + 1 + (end < 0)
        row, col = np.nonzero(np.arange(made.slots)[None, :] < steps[:, None])
        y.put(lanes.take(go.take(row)), first.take(row) + col, made.vertex(row, col))
    # The walk from the camera side.
    go = np.flatnonzero((camera_steps > 0) & ok)
    if go.size:
        rows, end = lanes.take(go), camera_end.take(go)
        start = y.vertex(rows, end)
        u = uniforms(3 * go.size).reshape(3, go.size)
        at_camera = end == y.k.take(rows)
        direction = camera_direction(scene, film_positions(scene.camera, u[:2]))
        surface = np.flatnonzero(~at_camera)
        if surface.size:
            here, after = end.take(surface), rows.take(surface)
            arriving = unit(y.p[:, after, here] - y.p[:, after, here + 1])
            direction[:, surface] = bsdf_direction(scene, _part(start, surface), arriving, "radiance", u[:, surface],
                                                   colours.take(go.take(surface)))
        made, reached = walk(scene, start, direction, camera_steps.take(go), "radiance", uniforms, colours.take(go))
        ok[go[reached < camera_steps.take(go)]] = False
        row, col = np.nonzero(np.arange(made.slots)[None, :] < camera_steps.take(go)[:, None])
        y.put(rows.take(row), end.take(row) - 1 - col, made.vertex(row, col))
    # The join.
    join = light_end + light_steps                      # the light side's last slot
    need = np.flatnonzero(ok & (join >= 0))
    if need.size:
        rows = lanes.take(need)
        a, b = y.vertex(rows, join.take(need)), y.vertex(rows, join.take(need) + 1)
        ok[need[~_visible(space.scene, a, b)]] = False
    return ok & (y.entity[lanes, 0] >= 0)


def _visible(scene, a: dict, b: dict) -> np.ndarray:
    """Whether vertices ``a`` and ``b`` (fields of :meth:`Paths.vertex`) are distinct and see each other."""
    apart = (a["p"] != b["p"]).any(axis=0)
    seen = np.zeros(apart.size, bool)
    k = np.flatnonzero(apart)
    if k.size:
        a, b = _part(a, k), _part(b, k)
        seen[k] = ~segment_blocked(scene, a["p"], a["eps"], a["n"], b["p"], b["eps"], b["n"])
    return seen


def _part(vertex: dict, idx: np.ndarray) -> dict:
    return {name: np.take(value, idx, axis=-1) for name, value in vertex.items()}


@dataclass
class FreshPaths:
    """Paths from independent pairs of walks (:func:`fresh_paths`; the paths of a pair share vertices): the
    paths, their values, ``density`` sum_j p_j
    (0 where a path was not made) and ``pair``, the walk pair each path came from."""

    paths: Paths
    values: PathValues
    density: np.ndarray
    pair: np.ndarray

    def weights(self) -> np.ndarray:
        """f / sum_j p_j (channels, n), 0 where a path was not made: summed over the paths of a pair, an unbiased
        estimate of the energy of the paths of its length."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.density > 0, self.values.f / self.density, 0.0)


def fresh_paths(space: Space, length: np.ndarray, slots: int, uniforms: Uniforms) -> FreshPaths:
    """Paths of ``length`` (pairs,) segments from independent pairs of walks, BDPT's way for one length
    (Veach 1997, sec. 10.2): for each pair of a light walk (a light point and L - 1 vertices) and a camera walk
    (L vertices from the pinhole through a uniform film position), the L + 1 paths made of the first j light-walk
    vertices and the first L - j camera-walk vertices, joined by a shadow ray (j = 0: the camera walk found a
    light).  Each path's ``density`` sums its densities over the L + 1 splits (:func:`split_densities`), so f / density
    is the multi-sample balance-heuristic weight (Veach 1997, sec. 9.2) and summed over a pair's paths
    estimates the energy b_L of paths of length L -- with L + 1 times less variance than one split chosen at
    random for paths only one split makes (a caustic seen through glass: only j = 0)."""
    scene, camera = space.scene, space.scene.camera
    count = length.size
    numbers = uniforms(count) if space.spectral else np.zeros(count)
    _, colours = space.colours(numbers)
    light_vertex, direction = light_points(scene, uniforms(5 * count).reshape(5, count))
    light_walk, light_reached = walk(scene, light_vertex, direction, length - 1, "importance", uniforms, colours)
    light_reached += 1                                      # the light point
    eye = dict(p=np.repeat(camera.position.astype(np.float32)[:, None], count, axis=1),
               n=np.repeat(camera.forward.astype(np.float32)[:, None], count, axis=1),
               eps=np.zeros(count, np.float32), material=np.full(count, -1, np.int64),
               entity=np.full(count, -1, np.int64))
    film = film_positions(camera, uniforms(2 * count).reshape(2, count))
    camera_walk, camera_reached = walk(scene, eye, camera_direction(scene, film), length, "radiance", uniforms,
                                       colours)
    # Path c comes from pair[c] with split j[c]: slots 0 .. j-1 from the light walk, j .. L-1 from the camera walk.
    pair = np.repeat(np.arange(count), length + 1)
    j = np.arange(pair.size) - np.repeat(np.cumsum(length + 1) - (length + 1), length + 1)
    k = length.take(pair)
    made = (light_reached.take(pair) >= j) & (camera_reached.take(pair) >= k - j)
    y = Paths.empty(pair.size, slots)
    y.k = np.where(made, k, 0)
    y.wavelength_number = numbers.take(pair)
    lanes = np.arange(pair.size)
    y.put(lanes, k, _part(eye, pair))
    slot = np.arange(slots)[None, :]
    row, col = np.nonzero(made[:, None] & (slot < j[:, None]) & (slot == 0))
    y.put(row, col, _part(light_vertex, pair.take(row)))
    row, col = np.nonzero(made[:, None] & (slot < j[:, None]) & (slot >= 1))
    y.put(row, col, light_walk.vertex(pair.take(row), col - 1))
    row, col = np.nonzero(made[:, None] & (slot >= j[:, None]) & (slot < k[:, None]))
    y.put(row, col, camera_walk.vertex(pair.take(row), k.take(row) - 1 - col))
    join = np.flatnonzero(made & (j >= 1))
    if join.size:
        seen = _visible(scene, y.vertex(join, j.take(join) - 1), y.vertex(join, j.take(join)))
        made[join[~seen]] = False
    y.k[~made] = 0
    values = evaluate(space, y)
    density = np.where(made, split_densities(values, np.zeros(pair.size, np.int64), k), 0.0)
    return FreshPaths(y, values, density, pair)


def bidirectional(space: Space, lengths: Lengths, x: Paths, xv: PathValues, uniforms: Uniforms) -> Proposed:
    """Veach's bidirectional mutation of paths ``x`` (see the module docstring)."""
    count, slots = x.count, x.slots
    k = x.k
    u = uniforms(4 * count).reshape(4, count)
    kd = lengths.pick_deletion(k, u[0])
    l = -1 + np.minimum((u[1] * (k - kd + 2)).astype(np.int64), k - kd + 1)
    m = l + kd
    ka = lengths.pick_addition(kd, u[2])
    k_new = k - kd + ka
    fits = (k_new <= lengths.max_depth) & (k_new >= lengths.min_length)
    new = ka - 1
    light = np.minimum((u[3] * (new + 1)).astype(np.int64), new)
    # y keeps x_0 .. x_l and x_m .. x_k, with the new vertices between.
    y = Paths.empty(count, slots)
    y.k = np.where(fits, k_new, 0)
    y.wavelength_number = _moved_wavelengths(space, x.wavelength_number, uniforms)
    slot = np.arange(slots)[None, :]
    gap_end = (l + new + 1)[:, None]                    # y's slot of x_m
    source = np.where(slot <= l[:, None], slot,
                      np.where((slot >= gap_end) & (slot <= k_new[:, None]), slot - gap_end + m[:, None], -1))
    row, col = np.nonzero((source >= 0) & fits[:, None])
    y.put(row, col, x.vertex(row, source[row, col]))
    go = np.flatnonzero(fits)
    ok = np.zeros(count, bool)
    ok[go] = _regenerate(space, y, go, l.take(go), light.take(go), (l + new + 1).take(go), (new - light).take(go),
                         uniforms)
    y.k[~ok] = 0
    yv = evaluate(space, y)
    # The split j is uniform over the k_a ways of making k_a - 1 new vertices (k_d for x's, backward).
    forward = lengths.p_deletion(k, kd) * lengths.p_addition(kd, ka) * split_densities(yv, l + 1, new) / ka
    backward = (lengths.p_deletion(np.where(ok, k_new, 1), np.where(ok, ka, 1)) * lengths.p_addition(ka, kd)
                * split_densities(xv, l + 1, kd - 1) / kd)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(ok & (forward > 0), backward / forward, 0.0)
    return Proposed(y, yv, np.where(np.isfinite(ratio), ratio, 0.0))


def _moved_wavelengths(space: Space, numbers: np.ndarray, uniforms: Uniforms) -> np.ndarray:
    """Spectral renders: the wavelength numbers after a symmetric small step on [0, 1) (Kelemen's exponential
    kernel), so that the chains explore the wavelengths too; T is unchanged in ratio.  RGB: as they are."""
    if not space.spectral:
        return numbers
    return (numbers + WAVELENGTH_STEP.steps(np.ones(numbers.size, np.int64), uniforms)) % 1.0


def _exponential(u: np.ndarray, low: float, high: float) -> np.ndarray:
    """Sizes with density ~ 1 / size between ``low`` and ``high`` (Veach 1997, sec. 11.4.3)."""
    return high * np.exp(-np.log(high / low) * u)


def _specular_run(xv: PathValues, k: np.ndarray, below: np.ndarray) -> np.ndarray:
    """The largest non-specular vertex index < ``below`` of each path (vertex 0, the light, never is)."""
    slots = xv.delta.shape[1]
    candidate = ~xv.delta & (np.arange(slots)[None, :] < below[:, None])
    return np.where(candidate.any(axis=1), slots - 1 - np.argmax(candidate[:, ::-1], axis=1), -1)


def _lobes(x: Paths, lanes: np.ndarray, slots: np.ndarray) -> np.ndarray:
    """The lobe numbers (n, steps) of the specular vertices at ``slots`` (n, steps; -1: none) of paths ``lanes``."""
    if x.slots < 3:   # paths of at most one segment have no scattering vertex
        return np.zeros(slots.shape)
    at = lanes[:, None] * x.slots + np.clip(slots, 1, x.slots - 2)   # flat (path, slot) positions
    p, n = x.p.reshape(3, -1), x.n.reshape(3, -1)
    numbers = lobe_numbers(np.take(p, at - 1, axis=1), np.take(p, at, axis=1), np.take(p, at + 1, axis=1),
                           np.take(n, at, axis=1))
    return np.where(slots >= 1, numbers, 0.0)


def _same_specular_chain(x: Paths, y: Paths, lanes: np.ndarray, low: np.ndarray, high: np.ndarray,
                         delta: np.ndarray) -> np.ndarray:
    """Whether y's vertices low .. high (exclusive) are specular with the lobes of x's, for paths ``lanes``."""
    width = int((high - low).max(initial=0))
    if width == 0:
        return np.ones(lanes.size, bool)
    slots = low[:, None] + np.arange(width)[None, :]
    inside = slots < high[:, None]
    slots = np.where(inside, slots, -1)
    same = _lobes(x, lanes, slots) == _lobes(y, lanes, slots)
    specular = delta[lanes[:, None], np.clip(slots, 0, x.slots - 1)]
    return (~inside | (same & specular)).all(axis=1)


def lens(space: Space, x: Paths, xv: PathValues, uniforms: Uniforms, radius: tuple[float, float]) -> Proposed:
    """Veach's lens perturbation of paths ``x``; ``radius`` (r1, r2) in pixels (see the module docstring)."""
    u = uniforms(2 * x.count).reshape(2, x.count)
    r, phi = _exponential(u[0], *radius), 2.0 * np.pi * u[1]
    return lens_to(space, x, xv, xv.raster + r * np.stack((np.cos(phi), np.sin(phi))), uniforms)


def lens_to(space: Space, x: Paths, xv: PathValues, raster: np.ndarray, uniforms: Uniforms) -> Proposed:
    """The lens perturbation of paths ``x`` that moves their film positions to ``raster`` (2, n)."""
    k = x.k
    lanes = np.arange(x.count)
    j, usable = _lens_source(x, xv)
    y, ok = _camera_chain(space, x, j, usable, raster, uniforms)
    yv = evaluate(space, y)
    ok &= _same_specular_chain(x, y, lanes, j + 1, k, yv.delta) & ~yv.delta[lanes, j]
    ok &= _joined(space, x, y, ok, j)
    return _perturbed(y, yv, ok, _jacobian(xv, k, j, k, "rev"), _jacobian(yv, k, j, k, "rev"))


def _lens_source(x: Paths, xv: PathValues) -> tuple[np.ndarray, np.ndarray]:
    """(j, usable): paths ... x_j S* E with x_j not specular and x_{j-1} not specular (or x_j the light), for the
    lens perturbation."""
    j = _specular_run(xv, x.k, x.k)
    return j, (x.k >= 1) & ((j == 0) | ~xv.delta[np.arange(x.count), np.maximum(j - 1, 0)])


def perturbable(x: Paths, xv: PathValues) -> np.ndarray:
    """(3, n) bool: whether the lens, caustic and multi-chain perturbations can move each of paths ``x`` (whether
    the path has the vertices each one moves).  This depends only on the path's length and which of its vertices
    are specular, which the perturbations keep; a bidirectional mutation can change it."""
    return np.stack([_lens_source(x, xv)[1], _caustic_source(x, xv)[1], _multichain_source(x, xv)[2]])


def _camera_chain(space: Space, x: Paths, j: np.ndarray, usable: np.ndarray, raster: np.ndarray,
                  uniforms: Uniforms) -> tuple[Paths, np.ndarray]:
    """A copy of paths ``x`` whose vertices j .. k-1 are remade by a walk from the camera through film positions
    ``raster`` (2, n) following x's specular lobes, where ``usable``; and whether the walk made them."""
    count, k = x.count, x.k
    scene = space.scene
    _, colours = space.colours(x.wavelength_number)
    camera = scene.camera
    inside = (raster[0] >= 0) & (raster[0] < camera.width) & (raster[1] >= 0) & (raster[1] < camera.height)
    go = np.flatnonzero(usable & inside)
    y = x.take(np.arange(count))
    ok = np.zeros(count, bool)
    if go.size:
        steps = (k - j).take(go)
        chain = k.take(go)[:, None] - 1 - np.arange(int(steps.max()))[None, :]      # the slots the walk makes
        lobes = _lobes(x, go, np.where(chain > j.take(go)[:, None], chain, -1))
        made, reached = walk(scene, x.vertex(go, k.take(go)), camera_direction(scene, raster[:, go]), steps,
                             "radiance", uniforms, colours.take(go), lobes)
        row, col = np.nonzero(np.arange(made.slots)[None, :] < steps[:, None])
        y.put(go.take(row), k.take(go).take(row) - 1 - col, made.vertex(row, col))
        ok[go] = reached == steps
    return y, ok


def _joined(space: Space, x: Paths, y: Paths, ok: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Where ``ok``: whether y's new vertex j joins x's kept vertex j - 1 (x_0 -- a light -- needs no join, but
    must be on an emitter)."""
    joined = ok & (y.entity[:, 0] >= 0)
    need = np.flatnonzero(joined & (j >= 1))
    if need.size:
        a, b = x.vertex(need, j.take(need) - 1), y.vertex(need, j.take(need))
        joined[need[~_visible(space.scene, a, b)]] = False
    return joined


def _multichain_source(x: Paths, xv: PathValues) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(j, i, usable): paths ... x_i S+ x_j S* E with x_i and x_j not specular (x_i's predecessor not specular
    either, or x_i the light), for the multi-chain perturbation."""
    k = x.k
    lanes = np.arange(x.count)
    j = _specular_run(xv, k, k)
    i = _specular_run(xv, k, j)
    usable = ((j >= 2) & xv.delta[lanes, np.maximum(j - 1, 0)]
              & ((i == 0) | ~xv.delta[lanes, np.maximum(i - 1, 0)]))
    return j, i, usable


def multichain(space: Space, x: Paths, xv: PathValues, uniforms: Uniforms, radius: tuple[float, float],
               angle: tuple[float, float]) -> Proposed:
    """Veach's multi-chain perturbation of paths ``x``: a lens perturbation to a new x_j, then the direction
    leaving it toward the light turned as by a caustic perturbation (see the module docstring)."""
    j, _, usable = _multichain_source(x, xv)
    lanes = np.arange(x.count)
    u = uniforms(4 * x.count).reshape(4, x.count)
    r, phi = _exponential(u[0], *radius), 2.0 * np.pi * u[1]
    raster = xv.raster + r * np.stack((np.cos(phi), np.sin(phi)))
    here = np.where(usable, j, 1)
    return multichain_to(space, x, xv, raster, _turned(unit(x.p[:, lanes, here - 1] - x.p[:, lanes, here]),
                                                       u[2:], angle), uniforms)


def multichain_to(space: Space, x: Paths, xv: PathValues, raster: np.ndarray, direction: np.ndarray,
                  uniforms: Uniforms) -> Proposed:
    """The multi-chain perturbation of paths ``x`` to film positions ``raster`` (2, n) that leaves the new x_j
    along unit ``direction`` (3, n) toward the light."""
    k = x.k
    lanes = np.arange(x.count)
    j, i, usable = _multichain_source(x, xv)
    y, ok = _camera_chain(space, x, j, usable, raster, uniforms)
    go = np.flatnonzero(ok)
    if go.size:
        jg, steps = j.take(go), (j - i).take(go)
        chain = jg[:, None] - 1 - np.arange(int(steps.max()))[None, :]
        lobes = _lobes(x, go, np.where(chain > i.take(go)[:, None], chain, -1))
        made, reached = walk(space.scene, y.vertex(go, jg), direction[:, go].astype(np.float32), steps, "importance",
                             uniforms, space.colours(x.wavelength_number.take(go))[1], lobes)
        row, col = np.nonzero(np.arange(made.slots)[None, :] < steps[:, None])
        y.put(go.take(row), jg.take(row) - 1 - col, made.vertex(row, col))
        ok[go] = reached == steps
    yv = evaluate(space, y)
    ok &= (_same_specular_chain(x, y, lanes, j + 1, k, yv.delta) & _same_specular_chain(x, y, lanes, i + 1, j, yv.delta)
           & ~yv.delta[lanes, j] & ~yv.delta[lanes, i])
    ok &= _joined(space, x, y, ok, i)
    return _perturbed(y, yv, ok, _jacobian(xv, k, i, k, "rev"), _jacobian(yv, k, i, k, "rev"))


def _turned(w: np.ndarray, u: np.ndarray, angle: tuple[float, float]) -> np.ndarray:
    """Unit directions (3, n) at angles theta1 .. theta2 (density ~ 1 / theta) from unit ``w`` about a uniform
    axis; ``u`` (2, n)."""
    theta, phi = _exponential(u[0], *angle), 2.0 * np.pi * u[1]
    s, t = orthonormal_basis(w)
    return unit(np.cos(theta) * w + np.sin(theta) * (np.cos(phi) * s + np.sin(phi) * t))


def _caustic_source(x: Paths, xv: PathValues) -> tuple[np.ndarray, np.ndarray]:
    """(j, usable): the vertex x_j whose outgoing direction a caustic perturbation turns -- the last non-specular
    vertex before x_{k-1} -- and whether the path has one (x_{k-1} not specular, k >= 2)."""
    k = x.k
    last = np.maximum(k - 1, 0)
    return _specular_run(xv, k, last), (k >= 2) & ~xv.delta[np.arange(x.count), last]


def caustic(space: Space, x: Paths, xv: PathValues, uniforms: Uniforms, angle: tuple[float, float]) -> Proposed:
    """Veach's caustic perturbation of paths ``x``; ``angle`` (theta1, theta2) in radians (see the module
    docstring)."""
    j, usable = _caustic_source(x, xv)
    u = uniforms(2 * x.count).reshape(2, x.count)
    lanes = np.arange(x.count)
    next_slot = np.where(usable, j + 1, 0)
    w = unit(x.p[:, lanes, next_slot] - x.p[:, lanes, np.where(usable, j, 0)])
    w = np.where(usable, w, np.array([[0.0], [0.0], [1.0]]))
    return caustic_toward(space, x, xv, _turned(w, u, angle), uniforms)


def caustic_toward(space: Space, x: Paths, xv: PathValues, direction: np.ndarray, uniforms: Uniforms) -> Proposed:
    """The caustic perturbation of paths ``x`` that sends the light leaving x_j along unit ``direction`` (3, n)."""
    count = x.count
    lanes = np.arange(count)
    k = x.k
    last = np.maximum(k - 1, 0)
    j, usable = _caustic_source(x, xv)
    go = np.flatnonzero(usable)
    y = x.take(lanes)
    ok = np.zeros(count, bool)
    if go.size:
        jg = j.take(go)
        steps = (k - 1 - j).take(go)
        chain = jg[:, None] + 1 + np.arange(int(steps.max()))[None, :]
        lobes = _lobes(x, go, np.where(chain < last.take(go)[:, None], chain, -1))
        made, reached = walk(space.scene, x.vertex(go, jg), direction[:, go].astype(np.float32), steps, "importance",
                             uniforms, space.colours(x.wavelength_number.take(go))[1], lobes)
        row, col = np.nonzero(np.arange(made.slots)[None, :] < steps[:, None])
        y.put(go.take(row), jg.take(row) + 1 + col, made.vertex(row, col))
        ok[go] = reached == steps
    yv = evaluate(space, y)
    ok &= _same_specular_chain(x, y, lanes, j + 1, last, yv.delta) & ~yv.delta[lanes, last]
    seen = np.flatnonzero(ok)
    if seen.size:
        a, b = y.vertex(seen, last.take(seen)), y.vertex(seen, k.take(seen))
        ok[seen[~_visible(space.scene, a, b)]] = False
    return _perturbed(y, yv, ok, _jacobian(xv, k, j + 1, k, "fwd"), _jacobian(yv, k, j + 1, k, "fwd"))


def _jacobian(values: PathValues, k: np.ndarray, low: np.ndarray, high: np.ndarray, side: str) -> np.ndarray:
    """The area density of vertices low .. high - 1 given the perturbed film position (``"rev"``: the camera's
    density at x_{k-1}, then the geometry factors behind specular vertices) or direction (``"fwd"``: geometry
    factors only, with Snell's Jacobian after each refraction, which a walk from the light needs to be in f's
    measure; see :mod:`pathspace.estimators.paths`)."""
    slot = np.arange(values.fwd.shape[1])[None, :]
    factor = values.g_rev if side == "rev" else values.g_fwd
    if side == "rev":
        factor = np.where(slot == (k - 1)[:, None], values.rev, factor)
    inside = (slot >= low[:, None]) & (slot < high[:, None])
    return np.where(inside, factor, 1.0).prod(axis=1)


def _perturbed(y: Paths, yv: PathValues, ok: np.ndarray, jacobian_x: np.ndarray, jacobian_y: np.ndarray) -> Proposed:
    """A perturbation's proposals: y, with f(y) = 0 where ``ok`` is False, and T(y -> x) / T(x -> y) = the
    Jacobian of x over y's."""
    yv.f = np.where(ok, yv.f, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = jacobian_x / jacobian_y
        ratio = np.where(ok & np.isfinite(ratio), ratio, 0.0)
    return Proposed(y, yv, ratio)
