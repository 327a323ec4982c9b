"""Finished sweep renders, cached so that a sweep run again renders only what it is missing.

A cell's render (one setting, one seed) is stored under the key of everything it depends on -- the
scene's fingerprint, the estimator and all its parameters, the seed, the budget, the threads it
rendered on and the code that rendered it (a hash of pathspace's source files and its C extension,
so that a changed estimator is never served an old image) -- as one ``.npz`` file (image, variance, statistics) in
``$PATHSPACE_CACHE/sweeps`` (default ``~/.cache/pathspace/sweeps``), written atomically as each render
finishes: a sweep that stops (the client lost its connection, the machine went down) loses only the
renders in flight.
"""
from __future__ import annotations

import hashlib
import json
import os
import warnings
import zipfile
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from ..imageio import atomic_output
from ..reference import cache_key, cache_root

__all__ = ["CellCache", "code_fingerprint"]


@lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """A hash of pathspace's Python sources and compiled extension (what renders an image)."""
    package = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for path in sorted(package.rglob("*.py")) + sorted(package.glob("_native*")):
        digest.update(str(path.relative_to(package)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


class CellCache:
    """Sweep renders by key in ``folder``; ``get`` gives None for a missing or unreadable entry."""

    def __init__(self, folder: str | os.PathLike | None = None) -> None:
        self.folder = Path(folder) if folder is not None else cache_root() / "sweeps"

    @classmethod
    def choose(cls, cache: Any, on_cluster: bool) -> "CellCache | None":
        """The cache a sweep's ``cache`` argument asks for: a folder, True (the default folder), False (none)
        or None (the default folder on a cluster, none in one process)."""
        if cache is None:
            return cls() if on_cluster else None
        if cache is True:
            return cls()
        if cache is False:
            return None
        if isinstance(cache, (str, os.PathLike)):
            return cls(cache)
        raise ValueError(f"cache: expected a folder, True, False or None, got {cache!r}")

    @staticmethod
    def key(scene, estimator, seed: int, spp: int | None, seconds: float | None, threads: int) -> str | None:
        """The key of a render on ``threads`` threads (its seconds, and with a time budget its image, depend
        on them), or None for a scene without a fingerprint (built by hand: not cached)."""
        if not scene.fingerprint:
            return None
        return cache_key({"scene": scene.fingerprint, "estimator": estimator.name, "params": estimator.params,
                          "seed": int(seed), "spp": spp, "time": seconds, "threads": int(threads),
                          "code": code_fingerprint()})

    def path(self, key: str) -> Path:
        return self.folder / f"{key}.npz"

    def get(self, key: str | None):
        """The cached render of ``key`` (an object with ``image``, ``variance``, ``stats``), or None."""
        from ..cluster.tasks import CellResult

        if key is None or not self.path(key).is_file():
            return None
        try:
            with np.load(self.path(key)) as data:
                return CellResult(data["image"], data["variance"], json.loads(str(data["stats"])))
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):  # a damaged entry: rendered again
            return None

    def put(self, key: str | None, result) -> None:
        """Store a finished render (``image``, ``variance``, ``stats``); a failure to write (a full disk) is
        a warning, not the end of the sweep."""
        if key is None:
            return
        try:
            with atomic_output(self.path(key)) as temporary, open(temporary, "wb") as file:
                np.savez(file, image=result.image, variance=result.variance,
                         stats=np.array(json.dumps(result.stats, default=str)))
        except OSError as error:
            warnings.warn(f"sweep cache: could not store a finished render in {self.folder}: {error}", stacklevel=2)
