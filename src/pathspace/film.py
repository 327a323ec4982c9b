"""The film: per-pixel sums and second moments of image estimates.

A film accumulates independent *samples* of each pixel -- one per pass, added
tile by tile (:meth:`Film.add_tile`) -- and from the sum and the sum of
squares of n samples reports the mean and the variance of the mean,
(sum_sq - sum^2 / n) / (n (n - 1)).

Non-finite samples (NaN, +-Inf in any channel) never reach the sums: they
are counted in ``nonfinite`` and left out of their pixel's sample count, so
the mean of the remaining samples stays unbiased when such failures are rare
and unrelated to the pixel's value (the count makes them visible either way).  Sums are float64 and are added, never
averaged, so films of disjoint sample ranges add up exactly (:meth:`merge`).
"""
from __future__ import annotations

import numpy as np

__all__ = ["Film"]


class Film:
    """Accumulators for a width x height image with ``channels`` channels (default 3: RGB)."""

    def __init__(self, width: int, height: int, channels: int = 3) -> None:
        self.width, self.height, self.channels = int(width), int(height), int(channels)
        pixels = self.width * self.height
        self.sum = np.zeros((self.channels, pixels))
        self.sum_sq = np.zeros((self.channels, pixels))
        self.count = np.zeros(pixels, dtype=np.int64)
        self.nonfinite = 0

    @property
    def pixel_count(self) -> int:
        """Number of pixels."""
        return self.width * self.height

    def add_tile(self, start: int, values: np.ndarray) -> None:
        """Add one sample to each of the pixels start .. start + N - 1: ``values`` is (channels, N)."""
        values = np.asarray(values, dtype=np.float64)
        stop = start + values.shape[1]
        finite = np.isfinite(values).all(axis=0)
        if not finite.all():
            self.nonfinite += int((~finite).sum())
            values = np.where(finite, values, 0.0)
        self.count[start:stop] += finite
        self.sum[:, start:stop] += values
        self.sum_sq[:, start:stop] += values * values

    def merge(self, other: "Film") -> None:
        """Add the samples of another film of the same size."""
        if (other.width, other.height, other.channels) != (self.width, self.height, self.channels):
            raise ValueError("films must have the same size and channels to merge")
        self.sum += other.sum
        self.sum_sq += other.sum_sq
        self.count += other.count
        self.nonfinite += other.nonfinite

    def mean(self) -> np.ndarray:
        """Per-pixel mean as an (height, width, channels) float64 image (0 where there are no samples)."""
        n = np.maximum(self.count, 1)
        return (self.sum / n).T.reshape(self.height, self.width, self.channels)

    def variance(self) -> np.ndarray:
        """Estimated variance of the per-pixel mean, (height, width, channels); inf below 2 samples."""
        n = self.count.astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            var = (self.sum_sq - self.sum * self.sum / n) / (n * (n - 1))
        var = np.where(n >= 2, np.maximum(var, 0.0), np.inf)
        return var.T.reshape(self.height, self.width, self.channels)
