"""The film: per-pixel means and second moments of independent image estimates, assembled pass by pass.

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
before the last of its samples.  An open pass holds one dense buffer (its
splats, then its samples added to them) and one per layer it has received;
splats are scattered into it where they land (``np.add.at`` per channel, in
one C pass with the GIL released: ``ext/film.c``), so no work item ever
allocates an image.  Samples of passes that never complete (a
render stopped in the middle of one) are never part of the estimate
(:meth:`discard_incomplete`).  Named *layers* (BDPT's per-strategy images)
receive splats only; each completed pass adds one sample to every layer (a
zero to a layer it did not reach), so layers have means and variances like
the image.

Moments
-------
Each pixel keeps the number n of its samples, their mean and M2, the sum of
squared deviations from the mean -- or, for films with ``covariance=True``,
the matrix of summed products of the deviations of every two channels.
They are updated with Welford's recurrence (B. P. Welford, "Note on a method
for calculating corrected sums of squares and products", Technometrics
4(3), 1962) in the pairwise form of Chan, Golub & LeVeque ("Algorithms for
computing the sample variance: analysis and recommendations", The American
Statistician 37(3), 1983, eq. 1.5): two sets of samples (n_a, mean_a, M2_a)
and (n_b, mean_b, M2_b) combine to

    n = n_a + n_b,   delta = mean_b - mean_a,   mean = mean_a + delta n_b / n,
    M2 = M2_a + M2_b + delta delta^T n_a n_b / n,

a new sample being the set n_b = 1, M2_b = 0.  No sum of squares is formed,
so nothing cancels: samples 1e8 + noise keep their variance, where the
one-pass (sum_sq - sum^2 / n) loses every digit.  To cover the whole float
range, a pixel stores its mean and M2 in units of 2^e and 4^e, with e the
binary exponent of the largest |sample| it has received (over channels), so
the stored values stay within [-1, 1] and [0, 4 n]: samples of 1e200 do not
overflow when squared and samples of 1e-200 do not underflow.  When a larger
sample arrives, e grows and the stored values are rescaled by a power of two
(``np.ldexp``: exact, but for bits below 2^-1074 of the new largest sample,
which float64 could not hold beside it anyway).

From the moments the film reports the mean, the variance of the mean
M2 / (n (n - 1)) and its square root, the standard error.  The standard
error is finite wherever the mean is; the variance of the mean of samples
beyond about 1e154 (or below 1e-162) is outside float64's range and comes
out inf (or 0) -- use :meth:`Film.standard_error` there.  Spectral renders
accumulate CIE XYZ and are looked at in linear sRGB, a linear map M of XYZ;
the variance of an sRGB channel needs the covariances of X, Y and Z, which
such films keep, and :meth:`Film.variance` applies M C M^T exactly.

Non-finite samples (NaN, +-Inf in any channel) never reach the moments: they
are counted in ``nonfinite`` and left out of their pixel's sample count, so
the mean of the remaining samples stays unbiased when such failures are rare
and unrelated to the pixel's value (the count makes them visible either way).

What is bit for bit: the moments depend only on the sequence of passes
committed (in the order they complete -- pass order under the default
loop), so a checkpoint after N passes equals a render of those N passes, on
any number of threads.  :meth:`Film.merge` combines films of disjoint pass
ranges with Chan's formula: the result equals the film of the union to
rounding (a few ulps), not bit for bit, and ``a.merge(b)`` rounds like
itself whatever the films hold (self first, then other).
"""
from __future__ import annotations

import numpy as np

from ._native import moments_add, splat_add

__all__ = ["Film", "Moments"]

# A pixel that has received only zeros (or nothing) keeps its moments in units of 2**SCALE_FLOOR, the
# binary exponent (as np.frexp gives it) of the smallest normal float; any non-zero sample raises it.
SCALE_FLOOR = np.frexp(np.finfo(np.float64).tiny)[1]
# Pixels per step when a pass joins the moments or the film is developed: the temporaries of one step
# stay in cache, and a large film needs no image-sized temporaries.
CHUNK_PIXELS = 1 << 15
# Pass statistics square the samples themselves while the largest is within 2**+-RAW_SQUARES (their sum
# cannot overflow, and squares that underflow are negligible beside the largest); beyond, they scale first.
RAW_SQUARES = 480


def _exponents(peak: np.ndarray) -> np.ndarray:
    """The binary exponent e of each ``peak`` (>= 0, finite): peak < 2**e, and e >= SCALE_FLOOR."""
    return np.frexp(np.maximum(peak, np.finfo(np.float64).tiny))[1]


class Moments:
    """Per-pixel count, mean and M2 of samples (see the module docstring), scaled per pixel by a power of two.

    ``count`` (pixels,) samples; ``exponent`` (pixels,) e; ``scaled_mean`` (C, pixels) mean / 2^e;
    ``scaled_m2`` (C, pixels) -- or (C, C, pixels) with ``covariance`` -- M2 / 4^e.  A new
    accumulator holds ``count`` samples of value zero (the state of a layer that no splat has reached
    in the passes so far).
    """

    def __init__(self, channels: int, pixels: int, covariance: bool, count: int = 0) -> None:
        self.covariance = bool(covariance)
        self.count = np.full(pixels, count, dtype=np.int64)
        self.exponent = np.full(pixels, SCALE_FLOOR, dtype=np.int32)
        self.scaled_mean = np.zeros((channels, pixels))
        self.scaled_m2 = np.zeros((channels, channels, pixels) if covariance else (channels, pixels))

    # -- accumulating -------------------------------------------------------------------------------

    def add(self, start: int, values: np.ndarray) -> np.ndarray:
        """Add one sample to each of the pixels start .. start + n - 1 (``values`` (C, n)); a column with a
        NaN or Inf is left out (its pixel's count does not grow).  Returns each column's largest |value|
        (not finite for the columns left out).  One pass in C with the GIL released (ext/film.c; the NumPy
        reference, :meth:`_raise_exponent` and :meth:`_combine` with one sample, is kept in the tests)."""
        values = np.asarray(values, dtype=np.float64)
        if not values.flags.aligned or (values.ndim == 2 and values.shape[1] > 1 and values.strides[1] != 8):
            values = np.array(values, order="C")   # the kernel reads aligned rows of any stride, columns contiguous
        return moments_add(self.count, self.exponent, self.scaled_mean, self.scaled_m2, start, values)

    def merge(self, other: "Moments") -> None:
        """Combine with another accumulator of the same pixels (Chan, Golub & LeVeque's pairwise update)."""
        exponent = self._raise_exponent(0, self.count.size, other.exponent)
        shift = other.exponent - exponent
        self._combine(0, self.count.size, other.count, np.ldexp(other.scaled_mean, shift),
                      np.ldexp(other.scaled_m2, 2 * shift))

    def _raise_exponent(self, start: int, stop: int, exponent: np.ndarray) -> np.ndarray:
        """Raise the exponents of pixels start .. stop - 1 to at least ``exponent``, rescaling their
        moments exactly (powers of two); returns the new exponents."""
        current = self.exponent[start:stop]
        grown = exponent > current
        if grown.any():
            grown = np.flatnonzero(grown)
            held = grown[self.count[start:stop][grown] > 0]  # pixels without samples have nothing to rescale
            shift = current[held] - exponent[held]
            at = held + start
            self.scaled_mean[:, at] = np.ldexp(self.scaled_mean[:, at], shift)
            self.scaled_m2[..., at] = np.ldexp(self.scaled_m2[..., at], 2 * shift)
            current[grown] = exponent[grown]
        return current

    def _combine(self, start: int, stop: int, count_b: np.ndarray | int, mean_b: np.ndarray,
                 m2_b: np.ndarray | None) -> None:
        """Chan et al.'s update of pixels start .. stop - 1 with a second set of ``count_b`` samples (per pixel,
        or 1 for all) of scaled mean ``mean_b`` (overwritten) and scaled M2 ``m2_b`` (None: 0), in the pixels'
        current units."""
        count_a = self.count[start:stop]
        count = count_a + count_b
        weight_b = 1.0 / count if isinstance(count_b, int) else count_b / np.maximum(count, 1)  # n_b / n
        mean = self.scaled_mean[:, start:stop]
        delta = np.subtract(mean_b, mean, out=mean_b)
        step = delta * weight_b
        mean += step
        np.multiply(delta, count_a * weight_b, out=step)       # delta n_a n_b / n
        if self.covariance:
            self.scaled_m2[:, :, start:stop] += delta[:, None, :] * step[None, :, :]
        else:
            self.scaled_m2[:, start:stop] += np.multiply(step, delta, out=step)
        if m2_b is not None:
            self.scaled_m2[..., start:stop] += m2_b
        self.count[start:stop] = count

    # -- developing ---------------------------------------------------------------------------------

    def mean(self, pixels: slice, matrix: np.ndarray | None = None) -> np.ndarray:
        """(C, k) mean of ``pixels`` (of ``matrix`` times it); 0 where there are no samples."""
        mean = self.scaled_mean[:, pixels]
        return np.ldexp(mean if matrix is None else matrix @ mean, self.exponent[pixels])

    def variance(self, pixels: slice, matrix: np.ndarray | None = None) -> np.ndarray:
        """(C, k) variance of the mean of ``pixels`` (of ``matrix`` times it); inf below 2 samples, and
        where it exceeds float64's range."""
        with np.errstate(over="ignore"):
            return np.ldexp(self._scaled_variance(pixels, matrix), 2 * self.exponent[pixels])

    def standard_error(self, pixels: slice, matrix: np.ndarray | None = None) -> np.ndarray:
        """(C, k) square root of :meth:`variance`, computed without leaving float64's range."""
        with np.errstate(over="ignore"):
            return np.ldexp(np.sqrt(self._scaled_variance(pixels, matrix)), self.exponent[pixels])

    def _scaled_variance(self, pixels: slice, matrix: np.ndarray | None) -> np.ndarray:
        """Variance of the mean in units of 4^e: M2 / (n (n - 1)), mapped by ``matrix``; inf below 2 samples."""
        n = self.count[pixels].astype(np.float64)
        m2 = self.scaled_m2[..., pixels]
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = 1.0 / (n * (n - 1))
            if self.covariance:
                m = np.eye(m2.shape[0]) if matrix is None else matrix
                var = np.einsum("ij,jkp,ik->ip", m, m2, m) * scale
            else:
                if matrix is not None:
                    raise ValueError("mapping the variance through a matrix needs a film with covariance=True")
                var = m2 * scale
        return np.where(n >= 2, np.maximum(var, 0.0), np.inf)

    @property
    def sum(self) -> np.ndarray:
        """(C, pixels) sums of the samples, n mean (derived from the moments)."""
        return np.ldexp(self.scaled_mean, self.exponent) * self.count

    @property
    def sum_sq(self) -> np.ndarray:
        """Sums of squares (C, pixels), or of channel products (C, C, pixels): M2 + n mean mean^T
        (derived from the moments; overflows to inf for samples beyond about 1e154)."""
        mean = self.scaled_mean
        outer = mean[:, None, :] * mean[None, :, :] if self.covariance else mean * mean
        with np.errstate(over="ignore"):
            return np.ldexp(self.scaled_m2 + outer * self.count, 2 * self.exponent)


class _Pass:
    """A pass being assembled: its splats and own-pixel samples in one buffer, its layers, and how many
    pixels have their sample."""

    def __init__(self, channels: int, pixels: int) -> None:
        self.channels, self.pixels = channels, pixels
        self.values = np.zeros((channels, pixels))
        self.layers: dict[str, np.ndarray] = {}
        self.covered = 0

    def buffer(self, layer: str | None) -> np.ndarray:
        """The buffer of the image (``layer`` None) or of a layer."""
        if layer is None:
            return self.values
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
        self.layers: dict[str, Moments] = {}
        self.passes = 0        # passes completed
        self.nonfinite = 0
        # Per completed pass: its largest |sample| (over pixels and channels), and the sum of its squared
        # samples divided by the square of that peak, so that neither overflows (how heavy the tail of the
        # samples is: see pathspace.diagnostics).
        self.pass_peaks: list[float] = []
        self.pass_relative_square_sums: list[float] = []
        self._open: dict[int, _Pass] = {}

    @property
    def pixel_count(self) -> int:
        """Number of pixels."""
        return self.width * self.height

    @property
    def count(self) -> np.ndarray:
        """(pixels,) number of (finite) samples of each pixel."""
        return self.moments.count

    @property
    def sum(self) -> np.ndarray:
        """(channels, pixels) sums of the image's samples (derived: :attr:`Moments.sum`)."""
        return self.moments.sum

    @property
    def sum_sq(self) -> np.ndarray:
        """Sums of squares (channels, pixels), or of channel products (channels, channels, pixels) (derived:
        :attr:`Moments.sum_sq`)."""
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
                self._commit(values, {})
                return
            self._open[pass_index] = _Pass(self.channels, self.pixel_count)
        assembly = self._open[pass_index]
        assembly.values[:, start:start + count] += values
        assembly.covered += count
        if assembly.covered == self.pixel_count:
            del self._open[pass_index]
            self._commit(assembly.values, assembly.layers)

    def add_splats(self, pass_index: int | np.ndarray, pixels: np.ndarray, values: np.ndarray,
                   layer: str | None = None) -> None:
        """Add ``values`` (C, n) to the samples of pass ``pass_index`` (one, or one per splat) of ``pixels`` (n,)
        -- of the image, or of the named ``layer``.  A pass's splats come before its last samples; the
        splats of a pass are added to each pixel in the order they arrive."""
        values = np.asarray(values, dtype=np.float64)
        pixels = np.asarray(pixels, dtype=np.int64)
        if values.shape != (self.channels, pixels.size):
            raise ValueError(f"splat values of shape {values.shape} for {pixels.size} pixels; expected "
                             f"({self.channels}, {pixels.size})")
        pass_index = np.asarray(pass_index, dtype=np.int64)
        if not pixels.size or not pass_index.size:   # nothing to add: no pass or layer is opened
            return
        if pass_index.ndim == 0 or pass_index.min() == pass_index.max():  # one pass (the usual case)
            self._scatter(int(pass_index.flat[0]), layer, pixels, values)
            return
        order = np.argsort(pass_index, kind="stable")  # by pass, each pass's splats in their order
        passes, first = np.unique(pass_index[order], return_index=True)
        for p, lo, hi in zip(passes.tolist(), first.tolist(), first[1:].tolist() + [order.size]):
            pick = order[lo:hi]
            self._scatter(p, layer, pixels[pick], values[:, pick])

    def _scatter(self, pass_index: int, layer: str | None, pixels: np.ndarray, values: np.ndarray) -> None:
        if pass_index not in self._open:
            self._open[pass_index] = _Pass(self.channels, self.pixel_count)
        splat_add(self._open[pass_index].buffer(layer), np.require(pixels, np.int64, "CA"),
                  np.require(values, np.float64, "CA"))

    def _commit(self, values: np.ndarray, layers: dict[str, np.ndarray]) -> None:
        """A complete pass (``values`` (C, pixels), and the layers it reached) joins the moments."""
        squares = _SquareSum()
        for start in range(0, self.pixel_count, CHUNK_PIXELS):
            squares.add(*self._commit_samples(self.moments, start, values[:, start:start + CHUNK_PIXELS]))
        self.pass_peaks.append(squares.peak)
        self.pass_relative_square_sums.append(squares.relative())
        for name in layers.keys() | self.layers.keys():
            if name not in self.layers:  # a layer reached for the first time: zero in the passes before
                self.layers[name] = Moments(self.channels, self.pixel_count, self.covariance, count=self.passes)
            values = layers.get(name)
            for start in range(0, self.pixel_count, CHUNK_PIXELS):
                stop = min(start + CHUNK_PIXELS, self.pixel_count)
                part = np.zeros((self.channels, stop - start)) if values is None else values[:, start:stop]
                self._commit_samples(self.layers[name], start, part)
        self.passes += 1

    def _commit_samples(self, moments: Moments, start: int, values: np.ndarray) -> tuple[np.ndarray, float]:
        """Add finite samples to ``moments`` (non-finite ones counted and left out); returns the samples
        added (those left out as zeros) and their largest |value|."""
        peak = moments.add(start, values)
        finite = np.isfinite(peak)
        if not finite.all():
            self.nonfinite += int(values.shape[1] - np.count_nonzero(finite))
            values, peak = np.where(finite, values, 0.0), np.where(finite, peak, 0.0)
        return values, float(peak.max(initial=0.0))

    def add_tile(self, start: int, values: np.ndarray) -> None:
        """Add one complete sample to each of the pixels start .. start + N - 1 (``values`` (C, N)),
        outside any pass (for accumulating samples by hand)."""
        self._commit_samples(self.moments, start, np.asarray(values, dtype=np.float64))

    @property
    def incomplete_passes(self) -> list[int]:
        """Passes that have received some but not all of their samples."""
        return sorted(self._open)

    def discard_incomplete(self) -> None:
        """Forget the passes that did not complete (a render stopped in the middle of them)."""
        self._open.clear()

    def merge(self, other: "Film") -> None:
        """Add the completed passes of another film of the same size (pairwise combination of the
        moments: equal to the film of both pass ranges to rounding, see the module docstring)."""
        if (other.width, other.height, other.channels, other.covariance) != (
                self.width, self.height, self.channels, self.covariance) or (
                (self.to_srgb is None) != (other.to_srgb is None)):
            raise ValueError("films must have the same size, channels and moments to merge")
        for name in sorted(self.layers.keys() | other.layers.keys()):
            if name not in self.layers:
                self.layers[name] = Moments(self.channels, self.pixel_count, self.covariance, count=self.passes)
            self.layers[name].merge(other.layers.get(name) or Moments(self.channels, self.pixel_count,
                                                                       self.covariance, count=other.passes))
        self.moments.merge(other.moments)
        self.passes += other.passes
        self.nonfinite += other.nonfinite
        self.pass_peaks += other.pass_peaks
        self.pass_relative_square_sums += other.pass_relative_square_sums

    # -- developing ---------------------------------------------------------------------------------

    def _develop(self, develop) -> np.ndarray:
        """An image (height, width, C) from ``develop(pixels)`` (C, k), a chunk of pixels at a time."""
        first = develop(slice(0, min(CHUNK_PIXELS, self.pixel_count)))
        out = np.empty((self.pixel_count, first.shape[0]))
        out[:first.shape[1]] = first.T
        for start in range(CHUNK_PIXELS, self.pixel_count, CHUNK_PIXELS):
            out[start:start + CHUNK_PIXELS] = develop(slice(start, start + CHUNK_PIXELS)).T
        return out.reshape(self.height, self.width, -1)

    def mean(self, matrix: np.ndarray | None = None) -> np.ndarray:
        """Per-pixel mean (height, width, channels), mapped by ``matrix`` if given; 0 where there are no samples."""
        return self._develop(lambda pixels: self.moments.mean(pixels, matrix))

    def variance(self, matrix: np.ndarray | None = None) -> np.ndarray:
        """Estimated variance of the per-pixel mean (of ``matrix`` times it); inf below 2 samples, and
        beyond float64's range (see :meth:`standard_error`)."""
        return self._develop(lambda pixels: self.moments.variance(pixels, matrix))

    def standard_error(self, matrix: np.ndarray | None = None) -> np.ndarray:
        """Estimated standard error of the per-pixel mean (the square root of :meth:`variance`), finite
        wherever the mean is, whatever the magnitude of the samples; inf below 2 samples."""
        return self._develop(lambda pixels: self.moments.standard_error(pixels, matrix))

    def image(self) -> np.ndarray:
        """The per-pixel mean in linear sRGB (height, width, 3), for RGB and spectral (XYZ) films alike."""
        return self.mean(self.to_srgb)

    def image_variance(self) -> np.ndarray:
        """The estimated variance of :meth:`image`."""
        return self.variance(self.to_srgb)

    def image_standard_error(self) -> np.ndarray:
        """The estimated standard error of :meth:`image`."""
        return self.standard_error(self.to_srgb)

    def layer_mean(self, name: str, matrix: np.ndarray | None = None) -> np.ndarray:
        """Mean of layer ``name`` per pixel over the completed passes (height, width, channels)."""
        return self._develop(lambda pixels: self.layers[name].mean(pixels, matrix))

    def layer_variance(self, name: str, matrix: np.ndarray | None = None) -> np.ndarray:
        """Estimated variance of :meth:`layer_mean`; inf below 2 passes."""
        return self._develop(lambda pixels: self.layers[name].variance(pixels, matrix))


class _SquareSum:
    """The largest |sample| of a pass and the sum of the squares of its samples, arriving in parts; the
    sum is kept as q 4^e, e the binary exponent of the peak so far, so that it never overflows."""

    def __init__(self) -> None:
        self.peak, self.exponent, self.scaled = 0.0, SCALE_FLOOR, 0.0

    def add(self, values: np.ndarray, peak: float) -> None:
        """Add the samples ``values`` (finite), whose largest |value| is ``peak``."""
        exponent = int(_exponents(np.float64(peak)))
        if exponent > self.exponent:
            self.scaled = float(np.ldexp(self.scaled, 2 * (self.exponent - exponent)))
            self.exponent = exponent
        self.peak = max(self.peak, peak)
        unit = np.ldexp(1.0, -self.exponent)
        if abs(self.exponent) <= RAW_SQUARES:  # squares of the values themselves neither overflow nor matter below
            self.scaled += float(np.einsum("ij,ij->", values, values)) * (unit * unit)
        else:
            scaled = values * unit
            self.scaled += float(np.einsum("ij,ij->", scaled, scaled))

    def relative(self) -> float:
        """The sum divided by the square of the peak (0 if the peak is 0)."""
        if self.peak == 0.0:
            return 0.0
        unit = float(np.ldexp(self.peak, -self.exponent))
        return self.scaled / (unit * unit)
