"""High-quality reference images, rendered once and cached while nothing they depend on changes.

``ps.reference(scene, estimator="pt", spp=4096)`` renders the scene (or
returns the cached render) and says how good it is: the cache holds an EXR
(image and variance) and a JSON file of metadata -- the scene's fingerprint
(a hash of its description and every file it loads), the estimator and its
parameters, spp, seed, colour mode, seconds, and the error the reference
predicts for itself (:func:`pathspace.metrics.predicted_relmse`).  A
reference is reused when all of these inputs match, and rendered again when
the scene (or a mesh or spectrum file it reads) changes.  The cache folder
is ``$PATHSPACE_CACHE/references`` (default ``~/.cache/pathspace/references``).
"""
from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .imageio import atomic_output, read_exr, write_exr
from .metrics import predicted_relmse
from .scene import Scene, load_scene

__all__ = ["Reference", "reference", "cache_folder", "cache_root", "cache_key"]


def cache_root() -> Path:
    """The root of pathspace's caches: ``$PATHSPACE_CACHE``, default ``~/.cache/pathspace``."""
    return Path(os.environ.get("PATHSPACE_CACHE") or os.path.join(os.path.expanduser("~"), ".cache", "pathspace"))


def cache_folder() -> Path:
    """Where references are cached: ``$PATHSPACE_CACHE/references``, default ``~/.cache/pathspace/references``."""
    return cache_root() / "references"


def cache_key(inputs: dict[str, Any]) -> str:
    """The key of a cached render: a hash of everything it depends on (``inputs``, JSON-able)."""
    return hashlib.sha256(json.dumps(inputs, sort_keys=True, default=str).encode()).hexdigest()[:20]


@dataclass
class Reference:
    """A reference image (linear sRGB), the variance of its per-pixel means, its metadata, its file, and
    whether it came from the cache."""

    image: np.ndarray
    variance: np.ndarray
    metadata: dict[str, Any]
    path: Path
    cached: bool = field(default=False)

    def summary(self) -> str:
        """One line: what it is and how good it is."""
        m = self.metadata
        return (f"reference {self.path.name}: {m['estimator']} {m['spp']} spp, seed {m['seed']}, "
                f"{m['seconds']:.1f} s{' (cached)' if self.cached else ''}; predicted relMSE "
                f"{m['predicted_relmse']:.3g} [{m['predicted_relmse_low']:.3g}, {m['predicted_relmse_high']:.3g}]")


def reference(scene: Scene | str | os.PathLike, estimator: str = "pt", *, spp: int = 4096, seed: int = 1,
              spectral: bool | None = None, folder: str | os.PathLike | None = None, force: bool = False,
              threads: int | None = None, progress: bool = False, client: Any = None, **params: Any) -> Reference:
    """The reference of ``scene``: from the cache if one with the same inputs exists (and not ``force``),
    else rendered with ``estimator`` (and its ``params``) at ``spp`` and cached -- on the cluster of
    ``client`` (a ``dask.distributed.Client``) if given (see :mod:`pathspace.cluster`)."""
    from .driver import render

    scene = scene if isinstance(scene, Scene) else load_scene(scene)
    inputs = {"scene": scene.fingerprint, "estimator": estimator, "params": dict(sorted(params.items())),
              "spp": int(spp), "seed": int(seed), "spectral": spectral}
    key = cache_key(inputs)
    folder = Path(folder) if folder is not None else cache_folder()
    stem = (Path(scene.source).parent.name if scene.source else "scene") + f"-{estimator}-{spp}spp-{key}"
    path = folder / f"{stem}.exr"
    if path.is_file() and path.with_suffix(".json").is_file() and not force:
        metadata = json.loads(path.with_suffix(".json").read_text())
        if metadata.get("key") == key:
            image, variance, _ = read_exr(path)
            return Reference(image.astype(np.float64), variance.astype(np.float64), metadata, path, cached=True)
    result = render(scene, estimator, spp=spp, seed=seed, spectral=spectral, threads=threads, progress=progress,
                    client=client, **params)
    predicted = predicted_relmse(result.image, result.variance, result.film.count.reshape(result.image.shape[:2]))
    metadata = {"key": key, **inputs, "scene_source": scene.source, "mode": result.stats["mode"],
                "seconds": result.stats["seconds"], "width": result.stats["width"], "height": result.stats["height"],
                "predicted_relmse": predicted.relmse, "predicted_relmse_low": predicted.low,
                "predicted_relmse_high": predicted.high, "nonfinite": result.stats["nonfinite"]}
    folder.mkdir(parents=True, exist_ok=True)
    write_exr(path, result.image, result.variance, {"reference": json.dumps(metadata, default=str)})
    with atomic_output(path.with_suffix(".json")) as temporary:
        temporary.write_text(json.dumps(metadata, indent=2, default=str))
    image, variance, _ = read_exr(path)  # what a later call will read: float32 pixels
    return Reference(image.astype(np.float64), variance.astype(np.float64), metadata, path)
