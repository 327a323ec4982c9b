"""What the render driver hands an estimator: work items, and how they are laid out."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["WorkItem", "TILE_PIXELS", "work_layout"]

# Wavefronts hold at most about this many paths: large enough to amortise
# Python's per-operation overhead, small enough for the arrays to stay in cache
# (measured fastest on the Cornell box among 2**14 .. 2**18).  A pass over a
# larger image is cut into equal tiles; a smaller image packs several passes
# into one wavefront.  Random streams belong to (pass, tile) units, so only the
# tiling of large images depends on this constant.
TILE_PIXELS = 1 << 16


def work_layout(pixel_count: int, passes: int | None, workers: int, tile_pixels: int = TILE_PIXELS
                ) -> tuple[int, int]:
    """(tile size in pixels, passes per work item) for an image of ``pixel_count`` pixels, in items of
    about ``tile_pixels`` lanes.

    Small images pack several passes into an item, but no more than keeps
    every worker busy when the number of ``passes`` is known.  The grouping
    changes neither the random streams nor the order of film additions.
    """
    tiles = -(-pixel_count // tile_pixels)
    tile = -(-pixel_count // tiles)
    if tiles > 1:
        return tile, 1
    per_item = max(1, tile_pixels // pixel_count)
    if passes is not None:
        per_item = min(per_item, max(1, -(-passes // (2 * workers))))
    return tile, per_item


@dataclass(frozen=True)
class WorkItem:
    """Passes ``passes`` of pixel tile ``tile`` (pixels ``pixel_start`` .. ``pixel_stop`` - 1).

    ``index`` numbers the items of a render in the order their results are
    added to the film.
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
