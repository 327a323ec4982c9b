"""Light tracing: light subpaths joined to the camera (the t = 1 strategies of BDPT), splatted.

Each pixel sample launches one light subpath; every vertex of it that can
scatter toward the camera (and the light point itself) is joined to a point
on the lens and its contribution lands on the pixel it projects to.  Paths
that reach the camera only through specular surfaces (a mirror seen by a
pinhole camera, caustics seen through glass) cannot be formed, so those
parts of the image stay black; everywhere else the estimate converges to
the same image as path tracing.  The light subpaths are joined to the camera
depth by depth while they are walked, and their vertices are not kept
(:func:`~pathspace.estimators.subpaths.stream_light_vertices`).

Parameters: ``max_depth``, the roulette parameters, ``diffuse_sampling``
and ``pyramid`` as for :mod:`pathspace.estimators.bdpt`; ``kernel``:
"fused" (default) takes the subpaths' vertices and joins them to a pinhole
camera in one C pass each where the scene allows (see
:func:`pathspace.estimators.pt_fused.walk_vertex` and
:mod:`pathspace.estimators.lens_fused`), "numpy" always in the NumPy code,
the reference (the same image bit for bit).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..sampler import Sampler
from ..spectra import RGBColours
from .base import Counters
from .bidirectional import Bidirectional
from .connections import Batch, Contributions, lens_samples
from .control import RenderControl
from .lens_fused import lens_kernel
from .subpaths import Subpaths, stream_light_vertices
from .wavefront import Lanes

__all__ = ["LightTracer"]


@dataclass
class LightTracer(Bidirectional):
    """Light tracer; see the module docstring for the parameters."""

    name = "lt"
    uses_camera_subpaths = False
    uses_lens_hits = False
    uses_densities = False  # every connection has weight 1

    def plan(self, scene) -> list[str]:
        """What this estimator will do on ``scene``, and what it leaves out and why."""
        depth = "unbounded" if self.max_depth < 0 else self.max_depth
        lines = [f"light tracing, max_depth={depth}", self._roulette_plan(), self._walk_plan(scene)]
        delta = scene.materials.delta_names
        if delta:
            lines.append(f"specular materials ({', '.join(delta)}): paths reaching the camera only through them "
                         "are not formed (those pixels miss that light)")
        if scene.lights.environment is not None:
            lines.append("environment seen directly: not formed (an infinite light cannot be joined to the camera)")
        fused, reason = lens_kernel(scene, RGBColours, {"diffuse_sampling": self.diffuse_sampling}, self.kernel)
        lines.append("vertices joined to the camera in one C pass (the fused kernel) in RGB, in NumPy when spectral"
                     if fused is not None else f"vertices joined to the camera in NumPy ({reason})")
        return lines

    def _subpaths(self, scene, mode, pixels: np.ndarray, samplers: Mapping[str, Sampler], units: np.ndarray,
                  counters: Counters, control: RenderControl,
                  chosen: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[Batch, Lanes]:
        """The connections of light subpaths to the camera, made while the subpaths are walked (a batch that keeps
        them in ``made``, and the light vertices 0 only), and the lanes' colour state."""
        if chosen is not None:
            return super()._subpaths(scene, mode, pixels, samplers, units, counters, control, chosen)
        state, settings = self._walk_settings(scene, mode, samplers, counters, control)
        batch: Batch | None = None

        def connect(vertices: Subpaths) -> None:
            nonlocal batch
            if batch is None:  # the vertices 0, one per lane: the batch reads the lanes' lights there
                batch = Batch(scene, vertices, None, None, settings.colours, settings.options, self.depth_limit,
                              units, densities=False, made=[], **self._kernels(scene, settings))
            part = lens_samples(batch, vertices)
            if part is not None:
                batch.made.append(part)
            if vertices.index.size:
                counters.longest = max(counters.longest, int(vertices.index[-1]))

        terminated = stream_light_vertices(settings, pixels.size, samplers["light"], connect)
        if terminated.any():
            mode.terminate_secondary(state, terminated)
        return batch, state

    def _kernels(self, scene, settings) -> dict:
        return {"lens_kernel": lens_kernel(scene, settings.colours, settings.options, self.kernel)[0]}

    def _contributions(self, batch: Batch):
        if batch.made is not None:
            yield from batch.made
        else:  # subpaths kept for chosen strategies (see Bidirectional.evaluate)
            part = lens_samples(batch)
            if part is not None:
                yield part

    def _weights(self, part: Contributions, batch: Batch) -> np.ndarray:
        return np.ones(part.count)
