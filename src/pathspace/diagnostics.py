"""What a render's running statistics say about it: exploding variance and paths of extreme length.

The film keeps, per pass, its largest |sample| and the sum of its squared
samples relative to that peak's square (so that neither overflows).
With finite variance the largest sample's share of the total second moment
falls as samples accumulate; with infinite variance (for instance a Russian
roulette that lifts throughputs faster than the surfaces absorb them, see
:func:`pathspace.roulette.roulette_warnings`) it stays large and the error
may grow with more samples.  Paths that reach extreme lengths are reported
too: light trapped without loss (total internal reflection in glass) costs
time and makes roulette matter.  The driver puts these findings, and the
estimator's own a-priori warnings, in ``stats["warnings"]``.
"""
from __future__ import annotations

import numpy as np

__all__ = ["LONG_PATH", "second_moment_share", "second_moment_warnings", "path_length_warnings"]

LONG_PATH = 1000          # segments: a path this long is reported
SHARE_LIMIT = 0.05        # a single sample holding more of the second moment than this is suspicious ...
MIN_PASSES = 8            # ... once there are this many passes


def second_moment_share(film) -> tuple[float, float]:
    """The largest single sample's share of the film's total second moment, over all passes and over the
    first half of them (0 before ``MIN_PASSES`` passes)."""
    peaks, relative = np.asarray(film.pass_peaks), np.asarray(film.pass_relative_square_sums)
    half = peaks.size // 2
    if peaks.size < MIN_PASSES or peaks[:half].max() <= 0:
        return 0.0, 0.0
    return _largest_share(peaks, relative), _largest_share(peaks[:half], relative[:half])


def _largest_share(peaks: np.ndarray, relative: np.ndarray) -> float:
    """max_p peak_p^2 / sum_p peak_p^2 relative_p, computed relative to the largest peak (no overflow)."""
    return float(1.0 / np.sum((peaks / peaks.max()) ** 2 * relative))


def second_moment_warnings(film) -> list[str]:
    """A warning if one sample holds a large share of the second moment and that share is not falling."""
    share, share_half = second_moment_share(film)
    if share > SHARE_LIMIT and share > 0.5 * share_half:
        return [f"one sample holds {share:.0%} of the second moment of all {film.passes} passes and that share is "
                f"not falling ({share_half:.0%} over the first half): the variance is exploding or infinite -- the "
                "error may grow with more samples, and the variance estimate is unreliable"]
    return []


def path_length_warnings(longest: int, truncated: int) -> list[str]:
    """A warning if paths reached ``LONG_PATH`` segments or were cut at the safety depth."""
    if longest < LONG_PATH and not truncated:
        return []
    return [f"paths of up to {longest} segments ({truncated} cut at the safety depth): light is trapped (e.g. "
            "total internal reflection in glass) -- a roulette that ends such paths, or max_depth, saves time"]
