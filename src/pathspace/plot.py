"""Figures of a paper's comparison section, one call each (matplotlib; the ``experiments`` extra).

``show`` (a tone-mapped image), ``grid`` (images side by side with labels),
``error_map`` (false-colour error image with a colour bar), ``crop`` and
``inset`` (a zoomed region), ``pyramid`` (Veach's per-strategy images),
``convergence_plot`` (log-log error against time with fitted slopes).
Images are linear RGB and are shown through :func:`pathspace.imageio.display`
(exposure in stops, clipped, sRGB-encoded).
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from .extras import optional_import
from .imageio import display

__all__ = ["show", "grid", "error_map", "crop", "inset", "pyramid", "convergence_plot"]


def _pyplot():
    return optional_import("matplotlib.pyplot", "figures")


def show(image: Any, ax=None, exposure: float = 0.0, title: str | None = None):
    """Draw an image (an array or anything with ``.image``) on ``ax`` (a new figure if None); returns ax."""
    plt = _pyplot()
    image = np.asarray(getattr(image, "image", image), dtype=np.float64)
    if ax is None:
        _, ax = plt.subplots(figsize=(4, 4 * image.shape[0] / image.shape[1]))
    ax.imshow(display(image, exposure), interpolation="nearest")
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title, fontsize=9)
    return ax


def grid(images: Mapping[str, Any] | Sequence[Any], columns: int | None = None, exposure: float = 0.0,
         size: float = 3.0):
    """Images side by side, labelled by their keys; returns the figure."""
    plt = _pyplot()
    items = list(images.items()) if isinstance(images, Mapping) else [(None, image) for image in images]
    columns = columns or len(items)
    rows = -(-len(items) // columns)
    figure, axes = plt.subplots(rows, columns, figsize=(size * columns, size * rows), squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    for ax, (label, image) in zip(axes.ravel(), items):
        show(image, ax, exposure, label)
    figure.tight_layout()
    return figure


def error_map(values: np.ndarray, ax=None, title: str | None = None, symmetric: bool = True, limit: float | None = None,
              cmap: str | None = None, label: str = ""):
    """A false-colour map of per-pixel values (mean over channels), e.g. a difference, relative error or
    z-score image from :mod:`pathspace.experiment.studies`, with a colour bar; returns ax."""
    plt = _pyplot()
    values = np.asarray(values, dtype=np.float64)
    if values.ndim == 3:
        values = values.mean(axis=2)
    finite = values[np.isfinite(values)]
    if limit is None:
        limit = float(np.percentile(np.abs(finite), 99)) if finite.size else 1.0
        limit = limit if limit > 0 else 1.0
    if ax is None:
        _, ax = plt.subplots(figsize=(4.6, 4 * values.shape[0] / values.shape[1]))
    lo, hi = (-limit, limit) if symmetric else (0.0, limit)
    shown = ax.imshow(values, cmap=cmap or ("RdBu_r" if symmetric else "magma"), vmin=lo, vmax=hi,
                      interpolation="nearest")
    ax.figure.colorbar(shown, ax=ax, fraction=0.046, pad=0.04, label=label)
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title, fontsize=9)
    return ax


def crop(image: np.ndarray, box: tuple[int, int, int, int]) -> np.ndarray:
    """The region ``box`` = (x, y, width, height) in pixels of an (H, W, ...) image."""
    x, y, w, h = box
    image = np.asarray(getattr(image, "image", image))
    if not (0 <= x < x + w <= image.shape[1] and 0 <= y < y + h <= image.shape[0]):
        raise ValueError(f"box {box} does not lie within the {image.shape[1]}x{image.shape[0]} image")
    return image[y:y + h, x:x + w]


def inset(ax, image: np.ndarray, box: tuple[int, int, int, int], where=(0.6, 0.6, 0.38, 0.38),
          exposure: float = 0.0, colour: str = "yellow"):
    """Mark ``box`` on the image shown in ``ax`` and draw its enlargement at ``where`` (axes fraction)."""
    from matplotlib.patches import Rectangle

    x, y, w, h = box
    ax.add_patch(Rectangle((x - 0.5, y - 0.5), w, h, fill=False, edgecolor=colour, linewidth=1))
    zoom = ax.inset_axes(where)
    show(crop(image, box), zoom, exposure)
    for spine in zoom.spines.values():
        spine.set_edgecolor(colour)
    return zoom


def pyramid(strategies: Mapping[tuple[int, int], Mapping[str, np.ndarray]], kind: str = "weighted",
            exposure: float = 0.0, size: float = 1.8, signed: bool = False):
    """Veach's pyramid (1997, fig. 10.3): row k holds the strategies of paths of k segments, s = 0 .. k + 1
    from the left; ``kind`` is "weighted", "unweighted" or "weight" (MIS-weight images, shown in [0, 1]);
    returns the figure."""
    plt = _pyplot()
    lengths = sorted({s + t - 1 for s, t in strategies})
    columns = max(lengths) + 2
    figure, axes = plt.subplots(len(lengths), columns, figsize=(size * columns, size * len(lengths)), squeeze=False)
    for row, k in enumerate(lengths):
        for s in range(columns):
            ax = axes[row, s]
            ax.axis("off")
            key = (s, k + 1 - s)
            if s > k + 1 or key not in strategies:
                continue
            values = strategies[key][kind]
            if kind == "weight":
                ax.imshow(np.nan_to_num(np.mean(values, axis=2), nan=0.0), vmin=0, vmax=1, cmap="viridis",
                          interpolation="nearest")
                ax.set_title(f"s={s}, t={k + 1 - s}", fontsize=8)
            else:
                show(values, ax, exposure, f"s={s}, t={k + 1 - s}")
    figure.tight_layout()
    return figure


def convergence_plot(convergence, metric: str = "relmse", x: str = "seconds", ax=None):
    """Log-log curves of a :class:`~pathspace.experiment.Convergence`: per estimator the mean over seeds (the
    range of the seeds shaded), labelled with the fitted slope; returns ax."""
    plt = _pyplot()
    if ax is None:
        _, ax = plt.subplots(figsize=(5.5, 4))
    table = convergence.table
    slopes = convergence.slopes(metric, x)["slope"]
    for label, runs in table.groupby("estimator", sort=False):
        stats = runs.groupby(runs.groupby("seed").cumcount())  # the k-th snapshot of every seed
        xs, mean = stats[x].mean(), stats[metric].mean()
        slope = f"slope {slopes[label]:.2f}" if label in slopes.index else "too few snapshots for a slope"
        line, = ax.plot(xs, mean, marker="o", markersize=3, label=f"{label} ({slope})")
        if runs["seed"].nunique() > 1:
            ax.fill_between(xs, stats[metric].min(), stats[metric].max(), color=line.get_color(), alpha=0.2)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel({"seconds": "render time (s)", "spp": "samples per pixel"}.get(x, x))
    ax.set_ylabel(metric)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return ax
