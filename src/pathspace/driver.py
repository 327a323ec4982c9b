"""The render driver: cut a render into work items, run them on threads, fill a film.

A render of ``spp`` samples per pixel is ``spp`` passes over the image.  Work
items hold at most about ``TILE_PIXELS`` paths: a tile of a large image, or
several passes of a small one (:func:`work_layout`); each (pass, tile) unit
has its own random stream (see :mod:`pathspace.sampler`).  One worker thread
per core runs the estimator over a wavefront that takes items as it needs
them -- NumPy and Embree release the GIL in their inner loops -- and results
are added to the film in item order, so the same seed gives the
bit-identical image whatever the thread count.
"""
from __future__ import annotations

import os
import time as _time
import threading
from dataclasses import dataclass, field
from typing import Any, Iterator

import numpy as np

from . import _native
from .film import Film
from .integrators import WorkItem, make_integrator, work_layout
from .scene import Scene, load_scene
from .spectra import RGBMode, SpectralMode

__all__ = ["render", "RenderResult"]

# Wavefront arrays are a few MB each and are allocated and freed many times a
# bounce.  By default glibc serves such blocks with fresh mmap()s or trims the
# heap after they are freed, so every allocation page-faults its memory back
# in; raising the two thresholds keeps them on the heap (measured: the Cornell
# box path tracer runs ~15% faster).  Set PATHSPACE_MALLOC_TUNING=0 to opt out.
MMAP_THRESHOLD = 32 << 20
TRIM_THRESHOLD = 256 << 20
_allocator_tuned = False


def _tune_allocator() -> None:
    global _allocator_tuned
    if not _allocator_tuned and os.environ.get("PATHSPACE_MALLOC_TUNING", "1") != "0":
        _native.tune_allocator(MMAP_THRESHOLD, TRIM_THRESHOLD)
    _allocator_tuned = True


@dataclass
class RenderResult:
    """A finished render.

    Attributes
    ----------
    image : (height, width, 3) float64, the per-pixel mean in linear sRGB
    variance : (height, width, 3) float64, estimated variance of that mean
    stats : estimator, parameters, colour mode and why, spp, seconds, samples per second, rays,
        nonfinite (pixel samples dropped at the film for a NaN or Inf), nonfinite_contributions
        (bidirectional estimators: connections whose value or MIS weight was NaN or Inf, dropped from
        their sample, which itself is kept), truncated (paths cut at the safety depth), longest_subpath
        (segments of the longest path, or subpath for bidirectional estimators), ...
    film : the film with the raw sums (RGB, or XYZ for spectral renders) for merging or further passes
    xyz : (height, width, 3) CIE XYZ of a spectral render (None for RGB renders)
    strategies : for bidirectional renders with ``pyramid`` > 0, {(s, t): {"unweighted": image,
        "weighted": image}} in linear sRGB: each strategy's mean contribution per pixel (None otherwise)
    """

    image: np.ndarray
    variance: np.ndarray
    stats: dict[str, Any]
    film: Film = field(repr=False)
    xyz: np.ndarray | None = field(default=None, repr=False)
    strategies: dict | None = field(default=None, repr=False)

    def summary(self) -> str:
        """One line: estimator, spp, time and throughput."""
        s = self.stats
        text = (f"{s['estimator']} ({s['mode']}): {s['spp']} spp at {s['width']}x{s['height']} in {s['seconds']:.2f} s "
                f"({s['samples_per_second'] / 1e6:.3f} M samples/s, {s['rays_per_second'] / 1e6:.2f} M rays/s, "
                f"{s['threads']} threads)")
        if s["nonfinite"]:
            text += f"; {s['nonfinite']} non-finite samples were dropped"
        if s["nonfinite_contributions"]:
            text += f"; {s['nonfinite_contributions']} non-finite connections were dropped"
        if s["truncated"]:
            text += f"; {s['truncated']} paths were cut at the safety depth"
        return text


def _work_items(pixel_count: int, passes: Iterator[int], tile: int, per_item: int) -> Iterator[WorkItem]:
    """Work items over the given passes, numbered in order; see :func:`work_layout`."""
    index = 0
    for group in _groups(passes, per_item):
        for start in range(0, pixel_count, tile):
            yield WorkItem(index, range(group[0], group[-1] + 1), start // tile, start, min(start + tile, pixel_count))
            index += 1


def _groups(passes: Iterator[int], size: int) -> Iterator[list[int]]:
    """Consecutive groups of ``size`` passes (the last may be shorter)."""
    group: list[int] = []
    for p in passes:
        group.append(p)
        if len(group) == size:
            yield group
            group = []
    if group:
        yield group


def render(scene: Scene | str | os.PathLike, estimator: str = "pt", *, spp: int | None = None,
           time: float | None = None, seed: int = 0, threads: int | None = None, progress: bool = False,
           first_pass: int = 0, spectral: bool | None = None, wavelength_sampling: str = "uniform",
           **params: Any) -> RenderResult:
    """Render ``scene`` with the named estimator.

    Parameters
    ----------
    scene : a Scene or the path of a scene file
    estimator : estimator name ("pt"); ``params`` are its parameters
    spp : samples (passes) per pixel; default 16 unless ``time`` is given
    time : a time budget in seconds instead of a sample count: passes are
        started until it is spent (at least one pass runs)
    seed : the seed of every random stream; the same seed gives the same image
    threads : worker threads (default: every core this process may use)
    progress : show a tqdm progress bar
    first_pass : index of the first pass; renders of disjoint pass ranges with
        the same seed are independent and their films add up (:meth:`Film.merge`)
        to the render of the union
    spectral : render spectrally (True), in RGB (False), or as the scene needs
        (None: spectral when it has measured spectra or dispersion)
    wavelength_sampling : "uniform" or "visible" (importance sampling of the
        visible range), for spectral renders
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    if spp is not None and time is not None:
        raise ValueError("give either spp or time, not both")
    if spp is None and time is None:
        spp = 16
    if spp is not None and not (isinstance(spp, (int, np.integer)) and spp >= 1):
        raise ValueError(f"spp: expected an integer >= 1, got {spp!r}")
    if time is not None and not (np.isfinite(time) and time > 0):
        raise ValueError(f"time: expected a number of seconds > 0, got {time!r}")
    if not (isinstance(seed, (int, np.integer)) and seed >= 0):
        raise ValueError(f"seed: expected an integer >= 0, got {seed!r}")
    if not (isinstance(first_pass, (int, np.integer)) and first_pass >= 0):
        raise ValueError(f"first_pass: expected an integer >= 0, got {first_pass!r}")
    threads = _native.default_thread_count() if threads is None else threads
    if not (isinstance(threads, (int, np.integer)) and threads >= 1):
        raise ValueError(f"threads: expected an integer >= 1, got {threads!r}")

    integrator = make_integrator(estimator, **params)
    integrator.check(scene)
    mode, mode_reason = _colour_mode(scene, spectral, wavelength_sampling)
    _tune_allocator()
    camera = scene.camera
    film = Film(camera.width, camera.height, covariance=mode.film_covariance)
    integrator.prepare(scene)  # build the BVHs it needs before the clock starts
    start = _time.perf_counter()
    deadline = None if time is None else start + time

    def passes() -> Iterator[int]:
        p = 0
        while (spp is not None and p < spp) or (deadline is not None and (p == 0 or _time.perf_counter() < deadline)):
            yield first_pass + p
            p += 1

    tile, per_item = work_layout(camera.pixel_count, spp, threads, integrator.tile_pixels)
    last_tile = -(-camera.pixel_count // tile) - 1
    items = _work_items(camera.pixel_count, passes(), tile, per_item)
    lock = threading.Lock()

    def next_item() -> WorkItem | None:
        with lock:
            return None if failures else next(items, None)

    # Each worker runs the estimator on its own wavefront, taking items as it needs them; results are added
    # to the film in item order, pass by pass, so the sums come out the same whatever the thread count.
    done = threading.Condition()
    results: dict[int, tuple] = {}
    failures: list[BaseException] = []
    counters = [{"rays": 0, "truncated": 0, "longest": 0, "nonfinite_contributions": 0} for _ in range(threads)]
    running = [threads]

    def work(k: int) -> None:
        try:
            for result in integrator.render_stream(scene, next_item, seed, mode, counters[k]):
                with done:
                    results[result[0].index] = result
                    done.notify()
        except BaseException as error:  # handed to the main thread
            failures.append(error)
        finally:
            with done:
                running[0] -= 1
                done.notify()

    bar = _progress_bar(progress, spp, estimator)
    workers = [threading.Thread(target=work, args=(k,), daemon=True) for k in range(threads)]
    for w in workers:
        w.start()
    done_passes = expected = 0
    pass_image = None      # a pass with splats, gathered tile by tile until its last tile is in
    strategy_sums: dict = {}
    while True:
        with done:
            while expected not in results and running[0] and not failures:
                done.wait()
            if failures:
                break
            if expected not in results:
                break
            item, values, splats, strategies = results.pop(expected)
        expected += 1
        width = item.pixel_stop - item.pixel_start
        for k in range(len(item.passes)):
            if splats is None:
                film.add_tile(item.pixel_start, values[:, k * width:(k + 1) * width])
                continue
            # A pass with splats is one sample of every pixel only once all its tiles are in.
            if pass_image is None:
                pass_image = np.zeros((3, camera.pixel_count))
            pass_image[:, item.pixel_start:item.pixel_stop] += values[:, k * width:(k + 1) * width]
            pass_image += splats[k]
            if item.tile == last_tile:
                film.add_tile(0, pass_image)
                pass_image = None
        for key, sums in (strategies or {}).items():
            if key in strategy_sums:
                strategy_sums[key] += sums
            else:
                strategy_sums[key] = sums
        if item.tile == last_tile:
            done_passes += len(item.passes)
            if bar is not None:
                bar.update(len(item.passes))
    for w in workers:
        w.join()
    if bar is not None:
        bar.close()
    if failures:
        raise failures[0]
    rays = sum(c["rays"] for c in counters)
    truncated = sum(c["truncated"] for c in counters)
    seconds = _time.perf_counter() - start
    samples = int(film.count.sum())
    stats = {
        "estimator": estimator,
        "params": {k: v for k, v in vars(integrator).items() if not k.startswith("_") and k != "roulette"},
        "plan": integrator.plan(scene),
        "spp": done_passes,
        "seed": int(seed),
        "first_pass": int(first_pass),
        "threads": int(threads),
        "width": camera.width,
        "height": camera.height,
        "seconds": seconds,
        "samples": samples,
        "samples_per_second": samples / seconds,
        "rays": rays,
        "rays_per_second": rays / seconds,
        "mode": mode.name,
        "mode_reason": mode_reason,
        "nonfinite": film.nonfinite,
        "nonfinite_contributions": sum(c["nonfinite_contributions"] for c in counters),
        "truncated": truncated,
        "longest_subpath": max(c["longest"] for c in counters),
        "scene": scene.source,
    }
    matrix = mode.film_to_srgb
    return RenderResult(image=film.mean(matrix), variance=film.variance(matrix), stats=stats, film=film,
                        xyz=film.mean() if mode.name == "spectral" else None,
                        strategies=_strategy_images(strategy_sums, done_passes, camera, matrix)
                        if strategy_sums else None)


def _strategy_images(sums: dict, passes: int, camera, matrix) -> dict:
    """Per-strategy mean images (linear sRGB) from per-strategy sums over ``passes`` passes."""
    out = {}
    for key in sorted(sums):
        images = {}
        for k, name in enumerate(("unweighted", "weighted")):
            mean = sums[key][k] / max(passes, 1)
            if matrix is not None:
                mean = matrix @ mean
            images[name] = mean.T.reshape(camera.height, camera.width, 3)
        out[key] = images
    return out


def _colour_mode(scene: Scene, spectral: bool | None, wavelength_sampling: str):
    """The colour mode of a render and the reason for it."""
    reasons = scene.spectral_reasons()
    if spectral is None:
        spectral = bool(reasons)
        reason = "; ".join(reasons) if reasons else "every colour in the scene is RGB and nothing disperses"
    else:
        reason = "asked for" + (f" (the scene: {'; '.join(reasons)})" if reasons else "")
        if reasons and not spectral:
            reason += ": spectra are reduced to RGB, dispersion uses the index at 550 nm"
    return (SpectralMode(wavelength_sampling) if spectral else RGBMode()), reason


def _progress_bar(enabled: bool, total: int | None, estimator: str):
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, unit="spp", desc=f"rendering ({estimator})", dynamic_ncols=True)
