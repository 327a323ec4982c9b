"""The film: per-pixel sums and second moments of image estimates.

A film accumulates independent *samples* of each pixel -- one per pass, added
tile by tile (:meth:`Film.add_tile`) -- and from the sum and the sum of
squares of n samples reports the mean and the variance of the mean,
(sum_sq - sum^2 / n) / (n (n - 1)).

Spectral renders accumulate CIE XYZ and are looked at in linear sRGB, a
linear map of XYZ; the variance of an sRGB channel then needs the covariances
of X, Y and Z, so such films keep all cross moments (``covariance=True``) and
:meth:`variance` applies the map exactly.

Non-finite samples (NaN, +-Inf in any channel) never reach the sums: they
are counted in ``nonfinite`` and left out of their pixel's sample count, so
the mean of the remaining samples stays unbiased when such failures are rare
and unrelated to the pixel's value (the count makes them visible either way).
Sums are float64 and are added, never averaged, so films of disjoint sample
ranges add up exactly (:meth:`merge`).
"""
from __future__ import annotations

import numpy as np

__all__ = ["Film"]


class Film:
    """Accumulators for a width x height image with ``channels`` channels (default 3)."""

    def __init__(self, width: int, height: int, channels: int = 3, covariance: bool = False) -> None:
        self.width, self.height, self.channels = int(width), int(height), int(channels)
        pixels = self.width * self.height
        self.sum = np.zeros((self.channels, pixels))
        # Second moments: the squares, or every product of two channels (channels x channels).
        self.covariance = bool(covariance)
        self.sum_sq = np.zeros((self.channels, self.channels, pixels) if covariance else (self.channels, pixels))
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
        if self.covariance:
            self.sum_sq[:, :, start:stop] += values[:, None, :] * values[None, :, :]
        else:
            self.sum_sq[:, start:stop] += values * values

    def merge(self, other: "Film") -> None:
        """Add the samples of another film of the same size."""
        if (other.width, other.height, other.channels, other.covariance) != (
                self.width, self.height, self.channels, self.covariance):
            raise ValueError("films must have the same size, channels and moments to merge")
        self.sum += other.sum
        self.sum_sq += other.sum_sq
        self.count += other.count
        self.nonfinite += other.nonfinite

    def _image(self, per_pixel: np.ndarray) -> np.ndarray:
        return per_pixel.T.reshape(self.height, self.width, per_pixel.shape[0])

    def mean(self, matrix: np.ndarray | None = None) -> np.ndarray:
        """Per-pixel mean (height, width, channels), mapped by ``matrix`` if given; 0 where there are no samples."""
        mean = self.sum / np.maximum(self.count, 1)
        return self._image(mean if matrix is None else matrix @ mean)

    def variance(self, matrix: np.ndarray | None = None) -> np.ndarray:
        """Estimated variance of the per-pixel mean (of ``matrix`` times it); inf below 2 samples."""
        n = self.count.astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = 1.0 / (n * (n - 1))
            if self.covariance:
                cov = (self.sum_sq - self.sum[:, None, :] * self.sum[None, :, :] / n) * scale
                m = np.eye(self.channels) if matrix is None else matrix
                var = np.einsum("ij,jkp,ik->ip", m, cov, m)
            else:
                if matrix is not None:
                    raise ValueError("mapping the variance through a matrix needs a film with covariance=True")
                var = (self.sum_sq - self.sum * self.sum / n) * scale
        var = np.where(n >= 2, np.maximum(var, 0.0), np.inf)
        return self._image(var)
