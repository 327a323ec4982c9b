"""Render state files: a render saved while it runs, and resumed where it stopped.

``ps.render(..., state_file=PATH, save_every=SECONDS)`` (and ``pathspace
render ... --save-every SECONDS``, whose state file is ``OUT.exr.state``)
saves the render's :class:`RenderState` -- its film, which passes it holds,
its render time and what identifies the render -- every ``save_every``
seconds and when the render is stopped (``RenderControl.stop``, SIGINT or
SIGTERM with ``stop_on_signal``); ``resume=True`` (``--resume``) continues
from it.  A state holds whole passes only (saves happen between work items,
with the clock paused, when no pass is half done), and a render's passes are
numbered and seeded independently of one another, so the resumed render
adds the remaining passes to the restored film in the same order as an
uninterrupted render would: the image is bit for bit the same, however
often the render was stopped or killed (SIGKILL included: the file on disk
is always a complete earlier save).

File format (version :data:`FORMAT`), written through
:func:`pathspace.imageio.atomic_output` (temporary file, fsync, rename):

* line 1: ``pathspace render state``;
* line 2: a JSON header: ``format``, ``pathspace`` (the version that wrote
  it), ``saved`` (UTC time), ``passes`` (completed), ``next_pass`` (the
  first pass still to render), ``seconds`` (render time so far), ``film``
  (the film's field layout) and ``render`` (what identifies the render:
  scene fingerprint, estimator and parameters, seed, first pass, spp or
  time budget, colour mode, wavelength sampling, resolution -- see
  :func:`render_identity`);
* the film, pickled whole (protocol 5);
* the SHA-256 digest (32 bytes) of everything before it.

A state file is a pickle: load only state files you wrote.
"""
from __future__ import annotations

import hashlib
import json
import pickle
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from . import __version__
from .estimators.base import Checkpoint
from .film import Film
from .imageio import atomic_output

__all__ = ["FORMAT", "Autosave", "RenderState", "StateError", "check_identity", "load_state", "open_state",
           "read_header", "render_identity", "save_state"]

FORMAT = 1
MAGIC = b"pathspace render state\n"
DIGEST_BYTES = 32  # SHA-256
HEADER_LIMIT = 1 << 20  # bytes: a longer second line is not a header
HEADER_FIELDS = {"format", "pathspace", "saved", "passes", "next_pass", "seconds", "film", "render"}


class StateError(ValueError):
    """A state file that cannot be read, or that belongs to another render."""


@dataclass
class RenderState:
    """What a render saves: ``render`` (its identity, :func:`render_identity`), the ``film`` of its
    completed passes, and its render ``seconds`` so far."""

    render: dict[str, Any]
    film: Film
    seconds: float

    @property
    def passes(self) -> int:
        """Completed passes: ``render["first_pass"]`` .. ``next_pass`` - 1."""
        return self.film.passes

    @property
    def next_pass(self) -> int:
        """The first pass still to render."""
        return self.render["first_pass"] + self.film.passes


def render_identity(scene, estimator, mode, *, seed: int, first_pass: int, spp: int | None,
                    time: float | None) -> dict[str, Any]:
    """What must not change between a render and its resumption, as JSON values: the scene's
    fingerprint, the estimator's name and the parameters that can change the image, the seed, the first
    pass, the budget (``spp`` or ``time``), the colour mode, its wavelength sampling (spectral renders) and
    the resolution."""
    return {"scene": scene.fingerprint, "estimator": estimator.name,
            "params": json.loads(json.dumps(estimator.image_params, sort_keys=True, default=str)),
            "seed": seed, "first_pass": first_pass, "spp": spp, "time": time, "mode": mode.name,
            "wavelengths": getattr(mode, "sampling", None),
            "resolution": [scene.camera.width, scene.camera.height]}


def check_identity(saved: dict[str, Any], now: dict[str, Any], path: str | Path) -> None:
    """Raise :class:`StateError` naming every setting in which the render ``now`` differs from the one
    whose state ``path`` holds (``saved``)."""
    differences = []
    for key in sorted(set(saved) | set(now)):
        before, after = saved.get(key), now.get(key)
        if before == after:
            continue
        if key == "scene":
            differences.append("scene: its fingerprint differs (the scene file, an override or a file it loads "
                               "has changed)")
        elif key == "params" and isinstance(before, dict) and isinstance(after, dict):
            differences += [f"params.{name}: {before.get(name)!r} in the state, {after.get(name)!r} now"
                            for name in sorted(set(before) | set(after)) if before.get(name) != after.get(name)]
        else:
            differences.append(f"{key}: {before!r} in the state, {after!r} now")
    if differences:
        raise StateError(f"{path} was saved by a different render ({'; '.join(differences)}); resume with the "
                         "same settings, or delete the file to start again")


def _layout(value: Any) -> Any:
    """The field names of a pathspace object, recursively into the pathspace objects it holds (None for
    anything else): how a film looks to the code that made it."""
    if not type(value).__module__.startswith("pathspace."):
        return None
    return {name: _layout(field) for name, field in sorted(vars(value).items())}


class _HashingWriter:
    """A binary file that also hashes what is written to it."""

    def __init__(self, file) -> None:
        self.file, self.digest = file, hashlib.sha256()

    def write(self, data) -> int:
        self.digest.update(data)
        return self.file.write(data)


def save_state(path: str | Path, state: RenderState) -> None:
    """Write ``state`` to ``path`` atomically (see the module docstring for the format)."""
    film = state.film
    if film.incomplete_passes:
        raise ValueError(f"a state holds whole passes only; passes {film.incomplete_passes} are incomplete")
    header = {"format": FORMAT, "pathspace": __version__,
              "saved": datetime.now(timezone.utc).isoformat(timespec="seconds"), "passes": state.passes,
              "next_pass": state.next_pass, "seconds": state.seconds, "film": _layout(film), "render": state.render}
    with atomic_output(path) as temporary, open(temporary, "wb") as file:
        writer = _HashingWriter(file)
        writer.write(MAGIC)
        writer.write(json.dumps(header, sort_keys=True).encode() + b"\n")
        pickle.dump(film, writer, protocol=5)
        file.write(writer.digest.digest())


def read_header(path: str | Path) -> dict[str, Any]:
    """The JSON header of the state file ``path`` (StateError if it is not one this pathspace reads)."""
    path = Path(path)
    with open(path, "rb") as file:
        magic = file.read(len(MAGIC))
        line = file.readline(HEADER_LIMIT)
    if magic != MAGIC:
        raise StateError(f"{path}: not a pathspace render state (expected it to start with {MAGIC.decode()!r})")
    try:
        header = json.loads(line)
    except ValueError:
        raise StateError(f"{path}: corrupt render state (its header is not JSON)") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        found = header.get("format") if isinstance(header, dict) else None
        raise StateError(f"{path}: render state format {found!r}; this pathspace reads format {FORMAT}")
    missing = sorted(HEADER_FIELDS - set(header))
    if missing or not isinstance(header["render"], dict):
        raise StateError(f"{path}: corrupt render state (its header lacks {', '.join(missing) or 'the render'})")
    return header


def load_state(path: str | Path) -> RenderState:
    """The :class:`RenderState` saved in ``path``, after checking that the file is whole (its digest)
    and that its film has the layout of this pathspace's films; StateError otherwise."""
    path = Path(path)
    header = read_header(path)
    size = path.stat().st_size
    with open(path, "rb") as file:
        digest = hashlib.sha256()
        remaining = size - DIGEST_BYTES
        while remaining > 0:
            chunk = file.read(min(remaining, 1 << 24))
            if not chunk:
                break
            digest.update(chunk)
            remaining -= len(chunk)
        if remaining != 0 or file.read(DIGEST_BYTES) != digest.digest():
            raise StateError(f"{path}: corrupt render state (its SHA-256 digest does not match: the file was cut "
                             "short or changed after it was written)")
        file.seek(len(MAGIC))
        file.readline(HEADER_LIMIT)
        try:
            film = pickle.load(file)
        except Exception as error:  # a payload that passed the digest but does not unpickle here
            raise StateError(f"{path}: the saved film cannot be read by this pathspace ({error!r}); resume with "
                             f"pathspace {header.get('pathspace')}, which saved it, or delete the file") from None
    fresh = Film(1, 1, covariance=getattr(film, "covariance", False))
    if not isinstance(film, Film) or _layout(film) != _layout(fresh):
        raise StateError(f"{path}: the saved film's fields differ from this pathspace's Film; resume with "
                         f"pathspace {header.get('pathspace')}, which saved it, or delete the file")
    if film.passes != header["passes"]:
        raise StateError(f"{path}: corrupt render state (the header says {header['passes']} passes, the film "
                         f"holds {film.passes})")
    return RenderState(header["render"], film, float(header["seconds"]))


def open_state(path: str | Path, render: dict[str, Any], resume: bool) -> RenderState | None:
    """The state to continue the render ``render`` (its identity) from: None if ``path`` does not exist
    (a fresh start); the saved state if ``resume``, after checking that it is this render's
    (:func:`check_identity`) and whole (:func:`load_state`).  An existing file without ``resume`` is an
    error: a new render would overwrite an unfinished one."""
    path = Path(path)
    if not path.exists():
        return None
    header = read_header(path)
    if not resume:
        saved = header["render"]
        budget = f"{header['passes']} of {saved['spp']} spp" if saved.get("spp") is not None else (
            f"{header['passes']} spp in {header['seconds']:.1f} of {saved.get('time')} s")
        raise StateError(f"{path} holds an unfinished render ({budget}, saved {header['saved']}): continue it "
                         "with resume=True (--resume on the command line), or delete the file to start again")
    check_identity(header["render"], render, path)
    return load_state(path)


class Autosave:
    """Saves a render's state (identity ``render``) to ``path`` when asked, and says when a periodic
    save is due: every ``every`` seconds of wall time (None: never)."""

    def __init__(self, path: str | Path, render: dict[str, Any], every: float | None) -> None:
        self.path, self.render, self.every = Path(path), render, every
        self.last = time.monotonic()
        self.saves = 0

    def due(self) -> bool:
        """Whether ``every`` seconds have passed since the start or the last save."""
        return self.every is not None and time.monotonic() - self.last >= self.every

    def save(self, checkpoint: Checkpoint) -> None:
        """Save the film and render time of ``checkpoint`` (whole passes)."""
        save_state(self.path, RenderState(self.render, checkpoint.film, checkpoint.seconds))
        self.last = time.monotonic()
        self.saves += 1
