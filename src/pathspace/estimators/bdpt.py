"""Bidirectional path tracing (Veach & Guibas 1995; Veach 1997, ch. 10) with every (s, t) strategy.

Each pixel sample builds a camera subpath and a light subpath and joins
them in every way the scene allows (see :mod:`pathspace.estimators.connections`):
s = 0 (the camera subpath hits a light), s = 1 (a light sample), t = 1 (a
lens sample, splatted), t = 0 (the light subpath passes through a thin lens,
splatted) and s, t >= 2 (a shadow ray between the two).  The strategies are
combined with multiple importance sampling; the weights come from ratios of
vertex densities computed in C (see ``ext/mis.c``).

Parameters
----------
max_depth : int, default -1
    Longest path in segments; -1 is unbounded (the full solution).
mis : "power" (default), "balance", "uniform", "single" or "none"
    The MIS heuristic (Veach 1997, sec. 9.2): "uniform" gives each strategy
    that can produce the path the weight 1 / (their number); "single" keeps
    only ``strategy`` (with weight 1 where it can produce the path), for
    debugging and per-strategy studies; "none" weighs every strategy 1, so the image is the *sum* of
    the strategies' estimates -- useful for variance figures, not an
    estimate of the image.
mis_beta : float, default 2
    Exponent of the power heuristic.
strategy : (s, t), for mis="single"
mis_strategies : None (all), a condition such as "s != 0 and t != 0", or [[s, t], ...]
    MIS over a subset of the strategies: the others get weight 0 and the
    weights are renormalised over the subset (see :class:`pathspace.mis.StrategySubset`).
rr, rr_depth, rr_probability, rr_cap : "albedo" (default), 1, 0.5, 1.0
    Russian roulette on both subpaths (see :mod:`pathspace.roulette`).
light_rr, light_rr_depth, light_rr_probability, light_rr_cap : None
    The light subpaths' own roulette (None: as the camera subpaths').
mis_roulette : "auto" (default), "both", "camera", "light" or "none"
    Which subpaths' local roulette (survival probabilities of "off", "fixed"
    and "albedo"; never "throughput", which depends on the walk) enters the
    vertex densities the MIS weights compare.  Every choice is unbiased and
    samples the same paths.  "auto" is "camera" where the light subpaths'
    roulette is "albedo" (the default) and "both" otherwise.  Leaving the
    light subpaths' albedo survival out gives 10% lower error at the same
    samples than "both" (SmallVCM's choice) on the diffuse Cornell box, 5-16%
    lower on six of the eleven other scenes in ``scenes/``, the same on
    three, 5-7% higher on the white furnace.  Albedo survival keeps a light
    subpath's throughput level; a "fixed" survival below the albedo raises
    it, and left out of the densities the weights no longer hold those
    paths back: with survival 0.3 ("fixed", rr_probability 0.7) on the light
    subpaths "camera" has 36 times the error of "both" on the diffuse box
    (docs/performance.md).  PSSMLT over BDPT and MLT's BDPT part take the
    default too.
diffuse_sampling : "cosine" (default) or "uniform"
pyramid : int, default 0
    Record, for every path length up to this many segments and every
    strategy (s, t), the unweighted and the weighted contribution images
    (Veach's pyramid; ``RenderResult.strategies``).
kernel : "fused" (default) or "numpy"
    "fused" takes the subpaths' vertices (BSDF sample, roulette, reverse
    density), joins light and camera vertices (s, t >= 2), camera vertices
    and light samples (s = 1), and light vertices and the camera (t = 1) in
    one C pass each where the scene allows (see
    :func:`pathspace.estimators.pt_fused.walk_vertex`,
    :mod:`pathspace.estimators.join_fused` and
    :mod:`pathspace.estimators.lens_fused`); "numpy" always in the NumPy
    code, the reference.  Both give the same image bit for bit.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..mis import SubpathPdfs, check_heuristic, mis_weights
from ..roulette import RussianRoulette
from ..spectra import RGBColours
from . import parameters as p
from .bidirectional import Bidirectional
from .connections import Batch, Contributions, emitter_hits, joins, lens_hits, lens_samples, light_samples
from .join_fused import join_kernel, light_sample_kernel
from .lens_fused import lens_kernel
from .subpaths import SubpathSettings

__all__ = ["BDPT"]


@dataclass
class BDPT(Bidirectional):
    """Bidirectional path tracer; see the module docstring for the parameters."""

    mis: str = p.mis_heuristic("power")
    mis_beta: float = p.mis_beta()
    strategy: tuple | None = p.mis_strategy()
    mis_strategies: object = p.mis_strategies()
    mis_roulette: str = p.mis_roulette()

    name = "bdpt"
    uses_lens_hits = True

    def __post_init__(self) -> None:
        super().__post_init__()
        self.mis, self.mis_beta, self.strategy = check_heuristic(self.mis, self.mis_beta, self.strategy,
                                                                 max_depth=self.max_depth)
        if self.mis == "single" and self.mis_strategies is not None:
            raise ValueError("mis_strategies: not used with mis='single' (which keeps one strategy already)")

    def _roulette_in_mis(self, light: RussianRoulette) -> tuple[bool, bool]:
        choice = self.mis_roulette
        if choice == "auto":   # leave out only a light roulette that keeps the throughput level (docstring)
            choice = "camera" if light.policy == "albedo" else "both"
        return choice in ("both", "camera"), choice in ("both", "light")

    def plan(self, scene) -> list[str]:
        """What this estimator will do on ``scene``, and what it leaves out and why."""
        depth = "unbounded" if self.max_depth < 0 else self.max_depth
        weights = {"power": f"power heuristic (beta={self.mis_beta:g})", "balance": "balance heuristic",
                   "uniform": "uniform weights over the strategies that can produce each path",
                   "single": f"only strategy (s, t) = {self.strategy}",
                   "none": "no MIS: every strategy weighted 1 (the image is the sum of the strategies)"}[self.mis]
        if self.mis_strategies is not None:
            weights += f", over the strategies {self.mis_strategies.spec!r} only (the others get weight 0)"
        lines = [f"bidirectional path tracing, max_depth={depth}; {weights}", self._roulette_plan(),
                 self._walk_plan(scene)]
        camera, lights = scene.camera, scene.lights
        lines.append("pinhole camera: no t = 0 strategy (rays cannot hit it)" if camera.delta_position
                     else "thin-lens camera: t = 0 strategy (light subpaths passing through the lens)")
        if lights.has_delta:
            lines.append("point/spot/directional lights: no s = 0 strategy for their paths (rays cannot hit them)")
        if lights.environment is not None:
            lines.append("environment: camera subpaths that leave the scene end on it (s = 0)")
        delta = scene.materials.delta_names
        if delta:
            lines.append(f"specular materials ({', '.join(delta)}): no connection through their vertices")
        options = {"diffuse_sampling": self.diffuse_sampling}
        for what, fused, reason in (("light and camera vertices joined",
                                     *join_kernel(scene, RGBColours, True, options, self.kernel)),
                                    ("camera vertices joined to light samples",
                                     *light_sample_kernel(scene, RGBColours, options, self.kernel)),
                                    ("light vertices joined to the camera",
                                     *lens_kernel(scene, RGBColours, options, self.kernel))):
            lines.append(f"{what} in one C pass (a fused kernel) in RGB, in NumPy when spectral" if fused is not None
                         else f"{what} in NumPy ({reason})")
        return lines

    def _kernels(self, scene, settings: SubpathSettings) -> dict:
        return {"join_kernel": join_kernel(scene, settings.colours, settings.densities, settings.options,
                                           self.kernel)[0],
                "lens_kernel": lens_kernel(scene, settings.colours, settings.options, self.kernel)[0],
                "light_kernel": light_sample_kernel(scene, settings.colours, settings.options, self.kernel)[0]}

    def check(self, scene) -> None:
        """Nothing in a scene stops BDPT (strategies a scene makes infeasible get weight 0)."""

    def _contributions(self, batch: Batch):
        for family in (emitter_hits, light_samples, lens_samples, lens_hits):
            part = family(batch)
            if part is not None:
                yield part
        yield from joins(batch)

    def _weights(self, part: Contributions, batch: Batch) -> np.ndarray:
        light, eye = batch.light, batch.eye
        return mis_weights(part, SubpathPdfs(light.offset, light.fwd, light.rev, light.delta),
                           SubpathPdfs(eye.offset, eye.fwd, eye.rev, eye.delta), part.flags,
                           batch.scene.camera.delta_position, self.mis, self.mis_beta,
                           self.strategy if self.strategy is not None else (-1, -1), subset=self.mis_strategies)
