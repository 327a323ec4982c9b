"""Per-strategy images of bidirectional renders: EXR layers and a labelled PNG contact sheet.

``RenderResult.strategies`` maps each strategy (s, t) to its unweighted and
MIS-weighted mean contribution images.  Laid out as in Veach (1997, fig.
10.3), row k holds the strategies of paths of k segments, s = 0 .. k + 1
from left to right (t = k + 1 - s); strategies that cannot produce any path
of the scene (t = 0 with a pinhole camera, ...) are drawn black and marked.
"""
from __future__ import annotations

import os

import numpy as np

from .imageio import atomic_output, to_srgb8

__all__ = ["strategy_layers", "write_contact_sheet"]

LABEL_HEIGHT = 14
GAP = 4


def strategy_layers(strategies: dict) -> dict[str, np.ndarray]:
    """EXR layers {"s1t2.weighted": image, ...} of every strategy's two images."""
    return {f"s{s}t{t}.{kind}": images[kind] for (s, t), images in sorted(strategies.items())
            for kind in ("unweighted", "weighted")}


def write_contact_sheet(path: str | os.PathLike, strategies: dict, kind: str = "weighted",
                        exposure: float = 0.0) -> None:
    """Write the ``kind`` ("weighted" or "unweighted") images of all strategies as one labelled PNG."""
    from PIL import Image, ImageDraw, ImageFont

    if kind not in ("weighted", "unweighted"):
        raise ValueError(f"kind: expected 'weighted' or 'unweighted', got {kind!r}")
    if not strategies:
        raise ValueError("no strategy images: render with pyramid > 0")
    height, width, _ = next(iter(strategies.values()))[kind].shape
    longest = max(s + t - 1 for s, t in strategies)
    cell_w, cell_h = width + GAP, height + LABEL_HEIGHT + GAP
    sheet = Image.new("RGB", (GAP + 40 + (longest + 2) * cell_w, GAP + longest * cell_h), (32, 32, 32))
    draw = ImageDraw.Draw(sheet)
    font = ImageFont.load_default()
    for k in range(1, longest + 1):
        top = GAP + (k - 1) * cell_h
        draw.text((GAP, top + LABEL_HEIGHT + height // 2 - 6), f"k={k}", fill=(230, 230, 230), font=font)
        for s in range(k + 2):
            t = k + 1 - s
            left = GAP + 40 + s * cell_w
            images = strategies.get((s, t))
            label = f"s={s} t={t}" + ("" if images is not None else " (none)")
            draw.text((left, top), label, fill=(230, 230, 230), font=font)
            if images is not None:
                sheet.paste(Image.fromarray(to_srgb8(images[kind], exposure), mode="RGB"), (left, top + LABEL_HEIGHT))
            else:
                draw.rectangle((left, top + LABEL_HEIGHT, left + width - 1, top + LABEL_HEIGHT + height - 1),
                               fill=(0, 0, 0))
    with atomic_output(path) as temporary:
        sheet.save(str(temporary), format="PNG")
