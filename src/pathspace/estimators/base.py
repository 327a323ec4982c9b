"""The estimator contract: what an estimator is given, what it returns, and who owns the loop.

An estimator is a dataclass whose fields are its parameters (declared with
:func:`parameter`: default, meaning and check in one place, so Python, the
command line and sweeps all reach them by name).  A render hands it a
:class:`RenderJob` -- the scene, the colour mode, a sampler source (the
estimator never creates its own random numbers; see
:mod:`pathspace.sampler`), the film, the thread count and the render's
:class:`~pathspace.estimators.control.RenderControl` -- and a
:class:`Budget`, and calls :meth:`Estimator.render`:

* The default :meth:`Estimator.render` is the passes x tiles loop of
  :func:`pathspace.estimators.passes.render_passes`: the render is cut into
  :class:`WorkItem` s (some passes over one tile of pixels), worker threads
  call :meth:`Estimator.render_items`, and every :class:`ItemResult` --
  own-pixel samples, splats, per-strategy layers, counters -- goes to the
  film in item order (:meth:`ItemResult.deliver`), which assembles passes.
  Path tracing, light tracing and BDPT only implement ``render_items``.
* An estimator without passes (a Markov chain) overrides ``render`` and
  feeds the film itself; it calls ``job.control.check()`` between steps and
  ``on_checkpoint`` when its budget says so, like the default loop.

Either way the film can be developed at every checkpoint without
restarting, and the image at a checkpoint of N passes equals a render of
those N passes with the same seed.
"""
from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar, Iterator

import numpy as np

from ..film import Film
from ..sampler import SamplerSource
from .control import RenderControl

__all__ = ["TILE_PIXELS", "Budget", "Checkpoint", "Counters", "Estimator", "ItemResult", "RenderJob", "Splats",
           "WorkItem", "counted", "parameter"]

# Wavefronts hold at most about this many paths: large enough to amortise Python's per-operation overhead,
# small enough for the arrays to stay in cache (measured fastest on the Cornell box among 2**14 .. 2**18).
# A pass over a larger image is cut into equal tiles; a smaller image packs several passes into one item.
# Random streams belong to (pass, tile) units, so only the tiling of large images depends on this constant.
TILE_PIXELS = 1 << 16


def parameter(default: Any, help: str, check: Callable[[Any, str], Any] | None = None, image: bool = True) -> Any:
    """An estimator parameter: a dataclass field with its meaning (``help``) and a validating
    ``check(value, name)`` that returns the value or raises ValueError("name: expected ..., got ...").
    ``image=False``: the parameter changes how the image is computed, not the image (a render saved with one
    value resumes with another; see :attr:`Estimator.image_params`)."""
    return field(default=default, metadata={"help": help, "check": check, "image": image})


@dataclass(frozen=True)
class WorkItem:
    """Passes ``passes`` of pixel tile ``tile`` (pixels ``pixel_start`` .. ``pixel_stop`` - 1).

    ``index`` numbers the items of a render in the order their results go to the film.
    """

    index: int
    passes: range
    tile: int
    pixel_start: int
    pixel_stop: int

    @property
    def keys(self) -> list[tuple[int, int]]:
        """Random-stream keys of the (pass, tile) units, in lane order."""
        return [(p, self.tile) for p in self.passes]

    @property
    def counts(self) -> list[int]:
        """Lanes per unit."""
        return [self.pixel_stop - self.pixel_start] * len(self.passes)

    @property
    def pixels(self) -> np.ndarray:
        """Pixel index of every lane: the tile's pixels, once per pass."""
        return np.tile(np.arange(self.pixel_start, self.pixel_stop, dtype=np.int64), len(self.passes))

    def pass_of(self, lanes: np.ndarray) -> int | np.ndarray:
        """The pass of each of ``lanes`` (lane indices, an array): an item of one pass gives that pass as an int
        (whatever ``lanes``), an item of several an int64 array like ``lanes``."""
        if len(self.passes) == 1:
            return self.passes[0]
        return np.asarray(self.passes, dtype=np.int64).take(np.asarray(lanes) // (self.pixel_stop - self.pixel_start))


@dataclass
class Splats:
    """Contributions that land anywhere on the film: ``value`` (3, n) film values at ``pixel`` (n,) in
    pass ``pass_index``: one for all (an int), or one per splat (n,)."""

    pass_index: int | np.ndarray
    pixel: np.ndarray
    value: np.ndarray


@dataclass
class Counters:
    """What a worker counts: rays traced, paths cut at the safety depth, the longest (sub)path in
    segments, and contributions dropped for a NaN or Inf (bidirectional connections)."""

    rays: int = 0
    truncated: int = 0
    longest: int = 0
    nonfinite_contributions: int = 0

    def merge(self, other: "Counters") -> None:
        """Add another worker's counts."""
        self.rays += other.rays
        self.truncated += other.truncated
        self.longest = max(self.longest, other.longest)
        self.nonfinite_contributions += other.nonfinite_contributions


@contextmanager
def counted(into: Counters, pieces: int) -> Iterator[list[Counters]]:
    """One :class:`Counters` per piece of work, merged into ``into`` when the block ends -- also when an
    interruption ends it, so that what the pieces traced counts."""
    own = [Counters() for _ in range(pieces)]
    try:
        yield own
    finally:
        for c in own:
            into.merge(c)


@dataclass
class ItemResult:
    """What a work item gives the film.

    ``samples`` (3, lanes): lane k's film value, the sample of pixel
    ``item.pixels[k]`` in pass ``item.passes[k // tile width]``; ``splats``: what
    lands elsewhere; ``layers``: per-strategy contributions by layer name
    (own-pixel ones included, as splats).
    """

    item: WorkItem
    samples: np.ndarray
    splats: list[Splats] = field(default_factory=list)
    layers: dict[str, list[Splats]] = field(default_factory=dict)

    def deliver(self, film: Film) -> None:
        """Add everything to ``film``: splats and layers first, then each pass's samples (which
        completes the pass once every tile is in)."""
        for splats in self.splats:
            film.add_splats(splats.pass_index, splats.pixel, splats.value)
        for name, parts in self.layers.items():
            for splats in parts:
                film.add_splats(splats.pass_index, splats.pixel, splats.value, layer=name)
        item = self.item
        width = item.pixel_stop - item.pixel_start
        for k, pass_index in enumerate(item.passes):
            film.add_samples(pass_index, item.pixel_start, self.samples[:, k * width:(k + 1) * width])


@dataclass
class Budget:
    """How long a render runs: ``spp`` passes, or the passes completed within ``seconds`` (work still
    in flight then is dropped), from pass ``first_pass`` on; ``checkpoints``: sorted counts of the
    passes rendered by this call, or render seconds (as ``checkpoint_unit`` says), at which the film
    is developed."""

    spp: int | None = None
    seconds: float | None = None
    first_pass: int = 0
    checkpoints: tuple[float, ...] = ()
    checkpoint_unit: str = "spp"


@dataclass
class Checkpoint:
    """The state of a render at a checkpoint: ``passes`` completed, render ``seconds`` so far (wall
    time minus pauses, checkpoints included), and the film (read it, do not keep or change it)."""

    passes: int
    seconds: float
    film: Film


@dataclass
class RenderJob:
    """Everything a render gives its estimator (see the module docstring)."""

    scene: Any
    mode: Any
    samplers: SamplerSource
    film: Film
    threads: int
    control: RenderControl
    progress: Any = None          # an object with update(passes), or None
    autosave: Any = None          # an object with due() -> bool and save(Checkpoint), or None (pathspace.resume)
    counters: Counters = field(default_factory=Counters)
    stats: dict = field(default_factory=dict)  # further statistics an estimator reports


class Estimator(ABC):
    """Base of every estimator; subclasses are dataclasses of :func:`parameter` fields."""

    name: ClassVar[str]
    tile_pixels: ClassVar[int] = TILE_PIXELS
    # Whether passes are independent estimates (so the film's variance across passes is the variance of its
    # mean); False for Markov chains, whose successive passes are correlated.
    independent_passes: ClassVar[bool] = True

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            check = f.metadata.get("check")
            if check is not None:
                setattr(self, f.name, check(getattr(self, f.name), f.name))

    @classmethod
    def parameters(cls) -> list[tuple[str, Any, str]]:
        """(name, default, meaning) of every parameter."""
        return [(f.name, f.default, f.metadata.get("help", "")) for f in dataclasses.fields(cls) if f.init]

    @property
    def params(self) -> dict[str, Any]:
        """The parameter values."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.init}

    @property
    def image_params(self) -> dict[str, Any]:
        """The values of the parameters that can change the image (all but those declared ``image=False``)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if f.init and f.metadata.get("image", True)}

    @abstractmethod
    def plan(self, scene) -> list[str]:
        """What this estimator will do on ``scene``, and what it leaves out and why."""

    def check(self, scene) -> None:
        """Raise ValueError if this estimator cannot render ``scene`` correctly."""

    def warnings(self, scene) -> list[str]:
        """What is wrong with these parameters on ``scene`` although it renders (e.g. infinite variance)."""
        return []

    def prepare(self, scene) -> None:
        """Build what the render needs before its clock starts (acceleration structures)."""
        scene.accel

    def render(self, job: RenderJob, budget: Budget,
               on_checkpoint: Callable[[Checkpoint], None] | None = None) -> None:
        """Render into ``job.film`` within ``budget``; the default is the passes x tiles loop."""
        from .passes import render_passes

        render_passes(self, job, budget, on_checkpoint)

    def render_items(self, job: RenderJob, next_item: Callable[[], WorkItem | None],
                     counters: Counters) -> Iterator[ItemResult]:
        """Render the items ``next_item()`` hands out (None: no more for now -- a worker refused under a time
        budget may ask again once its work in flight is done) on one worker, yielding their results as they
        finish; count into ``counters``."""
        raise NotImplementedError(f"{type(self).__name__} renders with its own loop; it has no work items")
