"""The film: per-pixel sums and second moments of independent image estimates, assembled pass by pass.

A render is a sequence of *passes*; each pass gives one independent sample
of every pixel.  Estimators hand the film two kinds of contribution:

``add_samples(pass, start, values)``
    the pixels start .. start + n - 1 receive their sample of ``pass`` (the
    radiance of camera paths through them, or a bidirectional estimator's
    own-pixel strategies);
``add_splats(pass, pixels, values, layer=None)``
    contributions that land on any pixel (light tracing's and BDPT's
    strategies that reach the camera through a lens sample or a lens hit),
    added to the sample of ``pass`` of the pixel they land on.

A pass is complete -- and its samples join the moments -- when every pixel
has received its ``add_samples``; a pass's splats must therefore be added
before the last of its samples.  Samples of passes that never complete (a
render stopped in the middle of one) are never part of the estimate
(:meth:`discard_incomplete`).  Named *layers* (BDPT's per-strategy images)
receive splats only; each completed pass adds one sample to every layer, so
layers have means and variances like the image.

From the sum and the sum of squares of n samples the film reports the mean
and the variance of the mean, (sum_sq - sum^2 / n) / (n (n - 1)).  Spectral
renders accumulate CIE XYZ and are looked at in linear sRGB, a linear map of
XYZ; the variance of an sRGB channel then needs the covariances of X, Y and
Z, so such films keep all cross moments (``covariance=True``) and
:meth:`variance` applies the map exactly.

Non-finite samples (NaN, +-Inf in any channel) never reach the sums: they
are counted in ``nonfinite`` and left out of their pixel's sample count, so
the mean of the remaining samples stays unbiased when such failures are rare
and unrelated to the pixel's value (the count makes them visible either way).
Sums are float64 and are added, never averaged, so films of disjoint pass
ranges add up (:meth:`merge`).
"""
from __future__ import annotations

import numpy as np

__all__ = ["Film", "Moments"]


class Moments:
    """Per-pixel sums of samples and of their squares (or of every product of two channels)."""

    def __init__(self, channels: int, pixels: int, covariance: bool) -> None:
        self.covariance = bool(covariance)
        self.sum = np.zeros((channels, pixels))
        self.sum_sq = np.zeros((channels, channels, pixels) if covariance else (channels, pixels))

    def add(self, start: int, values: np.ndarray) -> None:
        """Add one sample to each of the pixels start .. start + n - 1 (``values`` (C, n), finite)."""
        stop = start + values.shape[1]
        self.sum[:, start:stop] += values
        if self.covariance:
            self.sum_sq[:, :, start:stop] += values[:, None, :] * values[None, :, :]
        else:
            self.sum_sq[:, start:stop] += values * values

    def merge(self, other: "Moments") -> None:
        """Add another accumulator's sums."""
        self.sum += other.sum
        self.sum_sq += other.sum_sq

    def variance(self, count: np.ndarray, matrix: np.ndarray | None) -> np.ndarray:
        """(C, pixels) variance of the mean of ``count`` samples (of ``matrix`` times it); inf below 2."""
        n = np.asarray(count, dtype=np.float64)
        channels = self.sum.shape[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = 1.0 / (n * (n - 1))
            if self.covariance:
                cov = (self.sum_sq - self.sum[:, None, :] * self.sum[None, :, :] / n) * scale
                m = np.eye(channels) if matrix is None else matrix
                var = np.einsum("ij,jkp,ik->ip", m, cov, m)
            else:
                if matrix is not None:
                    raise ValueError("mapping the variance through a matrix needs a film with covariance=True")
                var = (self.sum_sq - self.sum * self.sum / n) * scale
        return np.where(n >= 2, np.maximum(var, 0.0), np.inf)


class _Pass:
    """A pass being assembled: its own-pixel samples, its splats, its layers, and how many pixels are in."""

    def __init__(self, channels: int, pixels: int) -> None:
        self.channels, self.pixels = channels, pixels
        self.samples = np.zeros((channels, pixels))
        self.splats: np.ndarray | None = None
        self.layers: dict[str, np.ndarray] = {}
        self.covered = 0

    def splat_buffer(self, layer: str | None) -> np.ndarray:
        if layer is None:
            if self.splats is None:
                self.splats = np.zeros((self.channels, self.pixels))
            return self.splats
        if layer not in self.layers:
            self.layers[layer] = np.zeros((self.channels, self.pixels))
        return self.layers[layer]


class Film:
    """Accumulators for a width x height image with ``channels`` channels (default 3)."""

    def __init__(self, width: int, height: int, channels: int = 3, covariance: bool = False,
                 to_srgb: np.ndarray | None = None) -> None:
        self.width, self.height, self.channels = int(width), int(height), int(channels)
        self.covariance = bool(covariance)
        self.to_srgb = to_srgb  # the matrix from the film's channels to linear sRGB (None: they are sRGB)
        self.moments = Moments(self.channels, self.pixel_count, self.covariance)
        self.count = np.zeros(self.pixel_count, dtype=np.int64)
        self.layers: dict[str, Moments] = {}
        self.passes = 0        # passes completed
        self.nonfinite = 0
        # Per completed pass: the sum over pixels and channels of its squared samples, and the largest one
        # (how heavy the tail of the samples is: see pathspace.experiment.diagnostics).
        self.pass_square_sums: list[float] = []
        self.pass_square_max: list[float] = []
        self._open: dict[int, _Pass] = {}

    @property
    def pixel_count(self) -> int:
        """Number of pixels."""
        return self.width * self.height

    @property
    def sum(self) -> np.ndarray:
        """(channels, pixels) sums of the image's samples."""
        return self.moments.sum

    @property
    def sum_sq(self) -> np.ndarray:
        """Sums of squares (channels, pixels), or of channel products (channels, channels, pixels)."""
        return self.moments.sum_sq

    # -- adding samples -----------------------------------------------------------------------------

    def add_samples(self, pass_index: int, start: int, values: np.ndarray) -> None:
        """The pixels start .. start + n - 1 receive their sample of pass ``pass_index`` (``values`` (C, n))."""
        values = np.asarray(values, dtype=np.float64)
        count = values.shape[1]
        if values.shape[0] != self.channels or not 0 <= start <= self.pixel_count - count:
            raise ValueError(f"samples of shape {values.shape} at pixel {start} do not fit a film of "
                             f"{self.channels} channels and {self.pixel_count} pixels")
        if pass_index not in self._open:
            if count == self.pixel_count:  # a whole pass at once, nothing pending: no assembly needed
                self._note_pass(self._commit_samples(0, values))
                self.passes += 1
                return
            self._open[pass_index] = _Pass(self.channels, self.pixel_count)
        assembly = self._open[pass_index]
        assembly.samples[:, start:start + count] = values
        assembly.covered += count
        if assembly.covered == self.pixel_count:
            self._commit(self._open.pop(pass_index))

    def add_splats(self, pass_index: int | np.ndarray, pixels: np.ndarray, values: np.ndarray,
                   layer: str | None = None) -> None:
        """Add ``values`` (C, n) to the samples of pass ``pass_index`` (one, or one per splat) of ``pixels`` (n,)
        -- of the image, or of the named ``layer``.  A pass's splats come before its last samples."""
        values = np.asarray(values, dtype=np.float64)
        pixels = np.asarray(pixels, dtype=np.int64)
        if values.shape != (self.channels, pixels.size):
            raise ValueError(f"splat values of shape {values.shape} for {pixels.size} pixels; expected "
                             f"({self.channels}, {pixels.size})")
        if np.ndim(pass_index) == 0:
            self._splat(int(pass_index), pixels, values, layer)
            return
        pass_index = np.asarray(pass_index, dtype=np.int64)
        if not pass_index.size:
            return
        first = int(pass_index.min())
        span = int(pass_index.max()) - first + 1
        slot = (pass_index - first) * self.pixel_count + pixels
        for c in range(self.channels):
            sums = np.bincount(slot, weights=values[c], minlength=span * self.pixel_count).reshape(span, -1)
            for k in range(span):
                self._buffer(first + k, layer)[c] += sums[k]

    def _splat(self, pass_index: int, pixels: np.ndarray, values: np.ndarray, layer: str | None) -> None:
        buffer = self._buffer(pass_index, layer)
        for c in range(self.channels):
            buffer[c] += np.bincount(pixels, weights=values[c], minlength=self.pixel_count)

    def _buffer(self, pass_index: int, layer: str | None) -> np.ndarray:
        if pass_index not in self._open:
            self._open[pass_index] = _Pass(self.channels, self.pixel_count)
        return self._open[pass_index].splat_buffer(layer)

    def _commit(self, assembly: _Pass) -> None:
        values = assembly.samples if assembly.splats is None else assembly.samples + assembly.splats
        self._note_pass(self._commit_samples(0, values))
        for name, values in assembly.layers.items():
            if name not in self.layers:
                self.layers[name] = Moments(self.channels, self.pixel_count, self.covariance)
            finite = np.isfinite(values).all(axis=0)
            if not finite.all():
                self.nonfinite += int(np.count_nonzero(~finite))
                values = np.where(finite, values, 0.0)
            self.layers[name].add(0, values)
        self.passes += 1

    def _commit_samples(self, start: int, values: np.ndarray) -> np.ndarray:
        """Add finite samples to the moments (non-finite ones counted and left out); returns what was added."""
        finite = np.isfinite(values).all(axis=0)
        if not finite.all():
            self.nonfinite += int((~finite).sum())
            values = np.where(finite, values, 0.0)
        self.count[start:start + values.shape[1]] += finite
        self.moments.add(start, values)
        return values

    def _note_pass(self, values: np.ndarray) -> None:
        squares = values * values
        self.pass_square_sums.append(float(squares.sum()))
        self.pass_square_max.append(float(squares.max(initial=0.0)))

    def add_tile(self, start: int, values: np.ndarray) -> None:
        """Add one complete sample to each of the pixels start .. start + N - 1 (``values`` (C, N)),
        outside any pass (for accumulating samples by hand)."""
        self._commit_samples(start, np.asarray(values, dtype=np.float64))

    @property
    def incomplete_passes(self) -> list[int]:
        """Passes that have received some but not all of their samples."""
        return sorted(self._open)

    def discard_incomplete(self) -> None:
        """Forget the passes that did not complete (a render stopped in the middle of them)."""
        self._open.clear()

    def merge(self, other: "Film") -> None:
        """Add the completed passes of another film of the same size."""
        if (other.width, other.height, other.channels, other.covariance) != (
                self.width, self.height, self.channels, self.covariance) or (
                (self.to_srgb is None) != (other.to_srgb is None)):
            raise ValueError("films must have the same size, channels and moments to merge")
        for name in set(self.layers) | set(other.layers):
            if name not in self.layers:
                self.layers[name] = Moments(self.channels, self.pixel_count, self.covariance)
            if name in other.layers:
                self.layers[name].merge(other.layers[name])
        self.moments.merge(other.moments)
        self.count += other.count
        self.passes += other.passes
        self.nonfinite += other.nonfinite
        self.pass_square_sums += other.pass_square_sums
        self.pass_square_max += other.pass_square_max

    # -- developing ---------------------------------------------------------------------------------

    def _image(self, per_pixel: np.ndarray) -> np.ndarray:
        return per_pixel.T.reshape(self.height, self.width, per_pixel.shape[0])

    def mean(self, matrix: np.ndarray | None = None) -> np.ndarray:
        """Per-pixel mean (height, width, channels), mapped by ``matrix`` if given; 0 where there are no samples."""
        mean = self.sum / np.maximum(self.count, 1)
        return self._image(mean if matrix is None else matrix @ mean)

    def variance(self, matrix: np.ndarray | None = None) -> np.ndarray:
        """Estimated variance of the per-pixel mean (of ``matrix`` times it); inf below 2 samples."""
        return self._image(self.moments.variance(self.count, matrix))

    def image(self) -> np.ndarray:
        """The per-pixel mean in linear sRGB (height, width, 3), for RGB and spectral (XYZ) films alike."""
        return self.mean(self.to_srgb)

    def image_variance(self) -> np.ndarray:
        """The estimated variance of :meth:`image`."""
        return self.variance(self.to_srgb)

    def layer_mean(self, name: str, matrix: np.ndarray | None = None) -> np.ndarray:
        """Mean of layer ``name`` per pixel over the completed passes (height, width, channels)."""
        mean = self.layers[name].sum / max(self.passes, 1)
        return self._image(mean if matrix is None else matrix @ mean)

    def layer_variance(self, name: str, matrix: np.ndarray | None = None) -> np.ndarray:
        """Estimated variance of :meth:`layer_mean`; inf below 2 passes."""
        return self._image(self.layers[name].variance(np.full(self.pixel_count, self.passes), matrix))
