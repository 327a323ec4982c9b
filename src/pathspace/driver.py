"""``render``: a scene, an estimator and a budget in; a developed film and its statistics out.

The driver knows no estimator: it validates the request, builds the job
(colour mode, film, sampler source, clock) and hands it to the estimator's
``render`` (see :mod:`pathspace.estimators.base`), which by default runs the
passes x tiles loop.  Checkpoints develop the film during the render without
restarting it.  A render given a ``state_file`` saves its state while it
runs and can be resumed from it (see :mod:`pathspace.resume`).
"""
from __future__ import annotations

import base64
import os
import re
from contextlib import nullcontext
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Callable, Sequence

import numpy as np

from . import _native
from .checks import integer, number
from .diagnostics import path_length_warnings, second_moment_share, second_moment_warnings
from .estimators import Estimator, make_estimator
from .estimators.base import Budget, Checkpoint, RenderJob
from .estimators.control import RenderControl
from .film import Film
from .memory import check_render_memory
from .progress import progress_bar
from .resume import Autosave, open_state, render_identity
from .sampler import SamplerSource, StreamSamplers
from .scene import Scene, load_scene
from .spectra import colour_mode

__all__ = ["render", "RenderResult", "can_save_state"]

# Wavefront arrays are a few MB each and are allocated and freed many times a bounce.  By default glibc
# serves such blocks with fresh mmap()s or trims the heap after they are freed, so every allocation
# page-faults its memory back in; raising the two thresholds keeps them on the heap (measured: the Cornell
# box path tracer runs ~15% faster).  Set PATHSPACE_MALLOC_TUNING=0 to opt out.
MMAP_THRESHOLD = 32 << 20
TRIM_THRESHOLD = 256 << 20
_allocator_tuned = False
CLOCK = "render time: from the first work item to the last (scene loading and BVH builds excluded; checkpoints paused)"
DEFAULT_SPP = 16  # samples per pixel when neither the call nor the scene's [render] table says
_STRATEGY_LAYER = re.compile(r"s(\d+)t(\d+)\.(weighted|unweighted)")


def _tune_allocator() -> None:
    global _allocator_tuned
    if not _allocator_tuned and os.environ.get("PATHSPACE_MALLOC_TUNING", "1") != "0":
        _native.tune_allocator(MMAP_THRESHOLD, TRIM_THRESHOLD)
    _allocator_tuned = True


# What a Metropolis render's b (stats["metropolis"]["brightness"]) is the mean of, per ``contribution``.
_CONTRIBUTION_LABELS = {"luminance": " (luminance)", "xyz": " (X+Y+Z)", "max": " (max channel)"}


@dataclass
class RenderResult:
    """A finished render.

    Attributes
    ----------
    image : (height, width, 3) float64, the per-pixel mean in linear sRGB
    variance : (height, width, 3) float64, estimated variance of that mean; NaN (unknown) for estimators whose
        passes are correlated (Markov chains: estimate it from independent renders, e.g. seeds)
    stats : estimator, parameters, plan, colour mode and why, spp, seconds (of rendering: scene loading
        and BVH builds excluded; a resumed render's include its earlier sessions), samples per second,
        rays, nonfinite (pixel samples dropped at the film for a NaN or Inf), nonfinite_contributions
        (bidirectional connections dropped for a NaN or Inf value or weight; their sample is kept),
        truncated (paths cut at the safety depth), longest_subpath (segments of the longest path, or
        subpath for bidirectional estimators), budget ({"spp", "time"}: what was asked for), stopped
        (why the render stopped before the end of its budget, e.g. "SIGINT"; None), resumed ({"passes",
        "seconds"} restored from a state file; None), saves (of the state file), ... Rays, rates and
        the path counters cover this session only.
    film : the film with the raw sums (RGB, or XYZ for spectral renders) for merging or further passes
    xyz : (height, width, 3) CIE XYZ of a spectral render (None for RGB renders)
    """

    image: np.ndarray
    variance: np.ndarray
    stats: dict[str, Any]
    film: Film = field(repr=False)
    xyz: np.ndarray | None = field(default=None, repr=False)

    @cached_property
    def strategies(self) -> dict | None:
        """For bidirectional renders with ``pyramid`` > 0, {(s, t): {"unweighted": image, "weighted":
        image}} in linear sRGB: each strategy's mean contribution per pixel (None otherwise)."""
        out: dict = {}
        for name in sorted(self.film.layers):
            match = _STRATEGY_LAYER.fullmatch(name)
            if match:
                s, t, kind = int(match[1]), int(match[2]), match[3]
                out.setdefault((s, t), {})[kind] = self.film.layer_mean(name, self.film.to_srgb)
        return dict(sorted(out.items())) or None

    def __repr__(self) -> str:
        s = self.stats
        return (f"RenderResult({s['estimator']}, {s['mode']}, {s['spp']} spp, {s['width']}x{s['height']}, "
                f"{s['seconds']:.2f} s{', %d warning(s)' % len(s['warnings']) if s['warnings'] else ''})")

    def _repr_html_(self) -> str:
        """In Jupyter: the tone-mapped image and the summary line."""
        from html import escape

        from .imageio import png_bytes

        encoded = base64.b64encode(png_bytes(self.image)).decode("ascii")
        width = max(self.stats["width"], 256)
        return (f'<img src="data:image/png;base64,{encoded}" style="width:{width}px;image-rendering:pixelated"/>'
                f"<pre>{escape(self.summary())}</pre>")

    def summary(self) -> str:
        """One line: estimator, spp, time and throughput, and anything dropped."""
        s = self.stats
        text = (f"{s['estimator']} ({s['mode']}): {s['spp']} spp at {s['width']}x{s['height']} in {s['seconds']:.2f} s "
                f"({s['samples_per_second'] / 1e6:.3f} M samples/s, {s['rays_per_second'] / 1e6:.2f} M rays/s, "
                f"{s['threads']} threads)")
        if "metropolis" in s and "mutations" in s["metropolis"]:
            m = s["metropolis"]
            # b is the mean of the scalar the chains sample, which is the image's brightness only for luminance.
            kind = _CONTRIBUTION_LABELS.get((s.get("params") or {}).get("contribution"), "")
            if m.get("direct"):   # path-space MLT: the chains render the paths longer than BDPT's direct part
                kind += f" of paths over {m['direct']} segments"
            text += (f"; Metropolis: {m['chains']} chains, {m['mutations_per_second'] / 1e6:.3f} M mutations/s, "
                     f"mean contribution b{kind} {m['brightness']:.6g} +- {m['brightness_standard_error']:.2g} "
                     f"(bootstrap {m['bootstrap']}), longest rejection run {m['longest_rejection_run']}")
        if s["nonfinite"]:
            text += f"; {s['nonfinite']} non-finite samples were dropped"
        if s["nonfinite_contributions"]:
            text += f"; {s['nonfinite_contributions']} non-finite connections were dropped"
        if s["truncated"]:
            text += f"; {s['truncated']} paths were cut at the safety depth"
        if s["resumed"]:
            text += f"; resumed at {s['resumed']['passes']} spp, {s['resumed']['seconds']:.2f} s"
        if s["stopped"]:
            text += f"; stopped ({s['stopped']}) before the end of its budget"
        if s["warnings"]:
            text += f"; {len(s['warnings'])} warning(s): " + " | ".join(s["warnings"])
        return text


def render(scene: Scene | str | os.PathLike, estimator: str | Estimator = "pt", *, spp: int | None = None,
           time: float | None = None, seed: int = 0, threads: int | None = None, progress: bool = False,
           first_pass: int = 0, spectral: bool | None = None, wavelength_sampling: str = "uniform",
           checkpoints: Sequence[float] = (), on_checkpoint: Callable[[Checkpoint], None] | None = None,
           samplers: SamplerSource | None = None, state_file: str | os.PathLike | None = None,
           save_every: float | None = None, resume: bool = False, keep_state: bool = False,
           stop_on_signal: bool = False, client: Any = None, task_passes: int | None = None,
           **params: Any) -> RenderResult:
    """Render ``scene`` with an estimator (a name and its ``params``, or an :class:`Estimator`).

    ``spp`` samples (passes) per pixel (default: the scene's ``[render]`` spp, else 16), or ``time``: the
    passes complete within that many seconds of rendering (work in flight then is dropped; workers take no
    item they would not finish by then, so the render may end earlier, but not before half the time).
    ``seed`` seeds every random stream: the same seed gives the same image.
    ``threads``: workers (default: every core this process may use).
    ``first_pass``: renders of disjoint pass ranges with the same seed are
    independent and their films add up (:meth:`Film.merge`) to the render of
    their union.  ``spectral``: render spectrally (True), in RGB (False), or
    as the scene needs (None); ``wavelength_sampling``: "uniform" or
    "visible".  ``on_checkpoint(Checkpoint)`` is called, with the clock
    paused, when the render reaches each of ``checkpoints`` -- pass counts
    with ``spp``, seconds with ``time`` -- and the film can be developed
    there.  ``samplers``: the source of random numbers (default
    :class:`~pathspace.sampler.StreamSamplers` of ``seed``).

    Long renders (see :mod:`pathspace.resume`): with ``state_file``, the
    render's state (the film of its completed passes, its render time and
    what identifies it) is saved there every ``save_every`` seconds of wall
    time (None: only when stopped) and when it is stopped; the file is removed
    once the render completes its budget, unless ``keep_state`` (it then stays
    as last saved: the command line removes it once the image is written, so
    a crash in between loses no more than the time since that save).  An
    existing state file is an error unless ``resume``: then the render
    continues from it -- it must be the same render (scene, estimator and
    parameters, seed, budget, colour mode, resolution), and the result is
    bit for bit that of an uninterrupted render; ``resume`` without a state
    file starts afresh.
    With ``time``, the budget is the total render time of all sessions.
    ``stop_on_signal``: SIGINT (Ctrl-C) and SIGTERM stop the render cleanly
    -- the passes in flight are dropped, the state is saved, and the result
    of the completed passes is returned with ``stats["stopped"]`` naming the
    signal -- instead of raising KeyboardInterrupt (or ending the process).

    ``client``: a ``dask.distributed.Client``; the render's passes then run as single-threaded tasks of
    ``task_passes`` passes each (default: about eight tasks per worker thread) on the cluster's workers, and
    their films are merged in pass order (see :mod:`pathspace.cluster`): the image equals this render
    without a client to rounding.  Such a render takes ``spp`` (not ``time``), no ``threads``, checkpoints,
    state file or samplers, and an estimator on the passes loop (not a Markov chain).
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    if spp is not None and time is not None:
        raise ValueError("give either spp or time, not both")
    spp = (scene.render_spp or DEFAULT_SPP) if spp is None and time is None else spp
    spp = None if spp is None else integer(spp, "spp", low=1)
    time = None if time is None else number(time, "time", low=0.0, low_open=True, what="a number of seconds > 0")
    seed, first_pass = integer(seed, "seed", low=0), integer(first_pass, "first_pass", low=0)
    threads_given = threads is not None
    threads = integer(_native.default_thread_count() if threads is None else threads, "threads", low=1)
    checkpoints = tuple(sorted(number(c, "checkpoints", low=0.0, low_open=True) for c in checkpoints))
    if state_file is None and (save_every is not None or resume or keep_state):
        raise ValueError("save_every, resume and keep_state need a state_file")
    save_every = None if save_every is None else number(save_every, "save_every", low=0.0, low_open=True,
                                                         what="a number of seconds > 0")

    estimator = estimator if isinstance(estimator, Estimator) else make_estimator(estimator, **params)
    estimator.check(scene)
    mode, mode_reason = colour_mode(scene, spectral, wavelength_sampling)
    if client is not None or task_passes is not None:
        _check_distributable(client, estimator, spp, checkpoints, samplers, state_file, stop_on_signal,
                             threads_given)
        from .cluster.render import render_on_cluster

        run = render_on_cluster(client, scene, estimator, mode, spp=spp, seed=seed, first_pass=first_pass,
                                spectral=spectral, wavelength_sampling=wavelength_sampling, progress=progress,
                                task_passes=task_passes)
        return _result(scene, estimator, mode, mode_reason, run.film, run.counters, run.stats,
                       threads=run.threads, seed=seed, first_pass=first_pass, budget={"spp": spp, "time": None},
                       seconds=run.seconds)
    check_render_memory(scene, estimator, mode, threads)  # refuse, naming the setting, before the film exists
    _tune_allocator()
    identity = state = None
    if state_file is not None:
        _check_resumable(scene, estimator, samplers)
        identity = render_identity(scene, estimator, mode, seed=seed, first_pass=first_pass, spp=spp, time=time)
        state = open_state(state_file, identity, resume)
    if state is None:
        film = Film(scene.camera.width, scene.camera.height, covariance=mode.film_covariance,
                    to_srgb=mode.film_to_srgb)
    else:
        film = state.film
    restored, restored_samples = film.passes, int(film.count.sum())
    previous = state.seconds if state is not None else 0.0
    estimator.prepare(scene)  # build the BVHs it needs before the clock starts
    autosave = Autosave(state_file, identity, save_every) if state_file is not None else None
    bar = progress_bar(progress, spp, "spp", f"rendering ({estimator.name})", restored)
    job = RenderJob(scene, mode, samplers or StreamSamplers(seed), film, threads, RenderControl(), progress=bar,
                    autosave=autosave)
    if spp is not None:  # this session renders the passes after the restored ones
        budget = Budget(spp - restored, None, first_pass + restored, tuple(c - restored for c in checkpoints
                                                                           if c > restored), "spp")
    else:  # the clock starts at the earlier sessions' render time
        budget = Budget(None, time, first_pass + restored, tuple(c for c in checkpoints if c > previous), "seconds")
    job.control.start(previous)
    try:
        with job.control.stop_on_signals() if stop_on_signal else nullcontext():
            if budget.spp != 0 and (time is None or previous < time):
                estimator.render(job, budget, on_checkpoint)
    finally:
        if job.progress is not None:
            job.progress.close()
    seconds = job.control.elapsed()
    complete = film.passes >= spp if spp is not None else seconds >= time
    stopped = job.control.reason if job.control.cancelled and not complete else None
    if autosave is not None:
        if stopped:
            autosave.save(Checkpoint(film.passes, seconds, film))
        elif not keep_state:
            autosave.path.unlink(missing_ok=True)
    resumed = {"passes": restored, "seconds": previous} if state is not None else None
    extra = {**job.stats, "state_file": None if state_file is None else str(state_file),
             "saves": 0 if autosave is None else autosave.saves}
    return _result(scene, estimator, mode, mode_reason, film, job.counters, extra, threads=threads, seed=seed,
                   first_pass=first_pass, budget={"spp": spp, "time": time}, seconds=seconds,
                   previous=previous, restored_samples=restored_samples, stopped=stopped, resumed=resumed)


def _result(scene: Scene, estimator: Estimator, mode, mode_reason: str, film: Film, counters, extra: dict, *,
            threads: int, seed: int, first_pass: int, budget: dict, seconds: float, previous: float = 0.0,
            restored_samples: int = 0, stopped: str | None = None, resumed: dict | None = None) -> RenderResult:
    """The result of a render that has filled ``film``: its images, warnings and statistics (``counters``:
    what the workers counted; ``extra``: statistics the estimator or the render loop add; ``previous``
    seconds and ``restored_samples`` of earlier sessions of a resumed render)."""
    warnings = (estimator.warnings(scene) + second_moment_warnings(film)
                + path_length_warnings(counters.longest, counters.truncated))
    warnings += [] if scene.lights.count else ["the scene has no lights: the image is black"]
    if not film.passes:
        warnings.append(f"stopped ({stopped}) before any pass was complete: the image is empty" if stopped else
                        f"no pass was complete when the time budget ({budget['time']:g} s) ran out: the image is "
                        "empty; give more time (one pass of this scene takes longer)")
    samples = int(film.count.sum())
    session = seconds - previous  # render seconds of this call: what the rates and counters cover

    def rate(count: int) -> float:
        return count / session if session > 0 else 0.0

    stats = {"estimator": estimator.name, "params": estimator.params, "plan": estimator.plan(scene),
             "spp": film.passes, "seed": seed, "first_pass": first_pass, "threads": threads,
             "width": film.width, "height": film.height, "seconds": seconds, "samples": samples,
             "samples_per_second": rate(samples - restored_samples), "rays": counters.rays,
             "rays_per_second": rate(counters.rays), "mode": mode.name, "mode_reason": mode_reason,
             "nonfinite": film.nonfinite, "nonfinite_contributions": counters.nonfinite_contributions,
             "truncated": counters.truncated, "longest_subpath": counters.longest,
             "largest_sample_share": second_moment_share(film)[0], "warnings": warnings, "clock": CLOCK,
             "scene": scene.source, "budget": budget, "stopped": stopped, "resumed": resumed,
             "state_file": None, "saves": 0, **extra}
    variance = film.image_variance() if estimator.independent_passes else np.full(film.image().shape, np.nan)
    return RenderResult(image=film.image(), variance=variance, stats=stats, film=film,
                        xyz=film.mean() if mode.name == "spectral" else None)


def can_save_state(estimator: Estimator) -> bool:
    """Whether renders with ``estimator`` can be saved to a state file and resumed: estimators on the passes
    loop (whole, independent passes); not those with their own loop (Markov chains)."""
    return type(estimator).render is Estimator.render


def _check_distributable(client: Any, estimator: Estimator, spp: int | None, checkpoints: tuple, samplers,
                         state_file, stop_on_signal: bool, threads: bool) -> None:
    """Refuse a render on a cluster that its tasks could not reproduce, naming the setting."""
    if client is None:
        raise ValueError("task_passes: only for renders on a cluster (give client=)")
    if not hasattr(client, "submit"):
        raise ValueError(f"client: expected a dask.distributed.Client (pathspace.cluster.start_client(scheduler="
                         f"ADDRESS) joins a running cluster), got {client!r}")
    if spp is None:
        raise ValueError("time: a render on a cluster takes spp (its tasks are pass ranges); sweeps and "
                         "convergence runs on a cluster take time budgets per cell")
    if not can_save_state(estimator):
        raise ValueError(f"client: estimator {estimator.name!r} renders with its own loop of correlated passes "
                         "(Markov chains), which cannot be split into tasks; render independent seeds as the "
                         "cells of a sweep instead")
    for name, value in (("checkpoints", checkpoints), ("samplers", samplers), ("state_file", state_file),
                        ("stop_on_signal", stop_on_signal)):
        if value:
            raise ValueError(f"{name}: not available for renders on a cluster")
    if threads:
        raise ValueError("threads: a render on a cluster runs one single-threaded task per worker thread; "
                         "choose the workers' threads when starting them")


def _check_resumable(scene: Scene, estimator: Estimator, samplers: SamplerSource | None) -> None:
    """Refuse a ``state_file`` for renders that a state file cannot restore exactly."""
    if not can_save_state(estimator):
        raise ValueError(f"state_file: estimator {estimator.name!r} renders with its own loop; only estimators "
                         "on the passes loop (whole, independent passes) can be saved and resumed")
    if samplers is not None:
        raise ValueError("state_file: a render with its own samplers cannot be saved and resumed (a state "
                         "restores the seeded streams of its seed only)")
    if not scene.fingerprint:
        raise ValueError("state_file: the scene has no fingerprint (load it with load_scene or scene_from_dict), "
                         "so a resumed render could not check that it is the same scene")
