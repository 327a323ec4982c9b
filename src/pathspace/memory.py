"""How much memory a render needs, estimated before anything is allocated, and a clear refusal when it does not fit.

What grows with the image (per pixel, C channels; see :mod:`pathspace.film`):

* the moments of the image -- a sample count (8 bytes), a scale exponent (4),
  C means and C second moments, or C x C with ``covariance`` (spectral films),
  8 bytes each;
* the same for every per-strategy layer (``pyramid`` of light tracing and BDPT);
* the open pass the film is assembling: C values per pixel, and C per layer
  (one pass at a time once the image is larger than a work item; several
  small passes of at most a work item's lanes otherwise);
* the result's images: the mean and its variance in sRGB, and CIE XYZ for
  spectral renders.

What does not: each worker thread's wavefront and the results waiting to
reach the film, which hold a work item's lanes (:data:`TILE_PIXELS`) whatever
the resolution and the spp.  Their peak was measured per estimator on the
Cornell box (``benchmarks/memory.py``, see ``docs/memory.md``); scenes with
longer paths keep more subpath vertices in BDPT.  Joining a pass to the
moments and developing the film work a chunk of pixels at a time, so they
add no image-sized temporaries.

:func:`check_render_memory` compares the estimate with the memory this
machine has available (psutil, else ``os.sysconf``; a cgroup's limit when the
process runs in one) and raises :class:`RenderMemoryError`, naming the
setting to change, before the film is allocated.
"""
from __future__ import annotations

import os
from pathlib import Path

from .estimators.base import TILE_PIXELS, Estimator
from .estimators.bidirectional import Bidirectional

__all__ = ["RenderMemoryError", "available_memory", "check_render_memory", "estimate_render_memory", "memory_needs"]

# Peak memory of one worker thread's wavefront and of the results it hands the film, in bytes, per
# estimator, for work items of TILE_PIXELS lanes: measured on the Cornell box (benchmarks/memory.py);
# estimators not listed are assumed to need the most of these.
WAVEFRONT_BYTES = {"pt": 64 << 20, "lt": 160 << 20, "bdpt": 256 << 20}
CGROUP = Path("/sys/fs/cgroup")  # where a cgroup v2 memory limit is read (memory.max, memory.current)
_GIB = float(1 << 30)


class RenderMemoryError(MemoryError):
    """A render that would need more memory than the machine has available; the message names the setting
    to change."""


def memory_needs(width: int, height: int, estimator: Estimator, covariance: bool, spectral: bool, threads: int,
                 layers: int = 0) -> dict[str, int]:
    """Bytes a render of ``width`` x ``height`` pixels needs, by part: "film" (the image's moments),
    "layers" (the moments of ``layers`` per-strategy layers), "open pass" (the pass being assembled),
    "images" (the developed result) and "wavefronts" (``threads`` workers of ``estimator``).
    ``covariance``: the film keeps every channel product (spectral renders); ``spectral``: the result
    has an XYZ image beside sRGB."""
    pixels, channels = int(width) * int(height), 3
    moments = 8 + 4 + 8 * channels + 8 * (channels * channels if covariance else channels)
    return {"film": pixels * moments,
            "layers": layers * pixels * moments,
            "open pass": (1 + layers) * 8 * channels * max(pixels, TILE_PIXELS),
            "images": (3 if spectral else 2) * 8 * channels * pixels,
            "wavefronts": threads * WAVEFRONT_BYTES.get(estimator.name, max(WAVEFRONT_BYTES.values()))}


def estimate_render_memory(scene, estimator: Estimator, covariance: bool, threads: int,
                           spectral: bool | None = None) -> int:
    """Bytes a render of ``scene`` with ``estimator`` on ``threads`` workers needs beyond the scene and its
    BVH (see :func:`memory_needs`); ``spectral`` defaults to ``covariance`` (spectral films keep it)."""
    return sum(_needs(scene, estimator, covariance, threads, covariance if spectral is None else spectral).values())


def _needs(scene, estimator: Estimator, covariance: bool, threads: int, spectral: bool) -> dict[str, int]:
    layers = estimator.film_layers(scene) if isinstance(estimator, Bidirectional) else 0
    return memory_needs(scene.camera.width, scene.camera.height, estimator, covariance, spectral, threads, layers)


def available_memory() -> int:
    """Bytes this process can still allocate: the system's available memory (psutil, else the free pages
    of ``os.sysconf``), and no more than the headroom under a cgroup v2 memory limit."""
    try:
        import psutil

        available = int(psutil.virtual_memory().available)
    except ImportError:
        available = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    try:
        limit = (CGROUP / "memory.max").read_text().strip()
        if limit != "max":
            available = min(available, int(limit) - int((CGROUP / "memory.current").read_text()))
    except (OSError, ValueError):
        pass
    return available


def check_render_memory(scene, estimator: Estimator, mode, threads: int) -> None:
    """Raise :class:`RenderMemoryError` if a render of ``scene`` with ``estimator`` in colour ``mode`` on
    ``threads`` workers needs more memory than is available, naming what to change."""
    spectral = mode.name == "spectral"
    needs = _needs(scene, estimator, mode.film_covariance, threads, spectral)
    total, available = sum(needs.values()), available_memory()
    if total <= available:
        return
    camera = scene.camera
    parts = ", ".join(f"{name} {_gb(size)}" for name, size in sorted(needs.items(), key=lambda p: -p[1]) if size)
    advice = []
    per_pixel = (total - needs["wavefronts"]) / (camera.width * camera.height)
    # the share of the pixels that would fit, leaving a fifth of the available memory to everything else
    fits = (0.8 * available - needs["wavefronts"]) / per_pixel / (camera.width * camera.height)
    if fits > 0:
        size = [max(1, int(camera.width * fits ** 0.5)), max(1, int(camera.height * fits ** 0.5))]
        advice.append(f"lower camera.resolution to at most about {size[0]}x{size[1]} (--set camera.resolution="
                      f"[{size[0]},{size[1]}] on the command line, resolution={tuple(size)} in load_scene)")
    if needs["layers"]:
        advice.append("lower pyramid (-p pyramid=0 records no per-strategy layers)")
    if spectral:
        advice.append("render in RGB (--rgb; spectral films keep the XYZ covariance)")
    if needs["wavefronts"] > available / 4:
        advice.append(f"use fewer threads (--threads; {threads} now)")
    raise RenderMemoryError(f"rendering {camera.width}x{camera.height} with {estimator.name} needs ~{_gb(total)} "
                            f"({parts}), and this machine has {_gb(available)} available; " + " or ".join(advice))


def _gb(size: float) -> str:
    """A byte count in GB, to three significant digits (whole GB above a thousand)."""
    gb = size / _GIB
    return f"{gb:,.0f} GB" if gb >= 1000 else f"{gb:.3g} GB"
