"""Do two renders estimate the same image?  A block-wise z-test with multiple-comparison control.

Each render comes with the estimated variance of its per-pixel means.  Pixels
are pooled into square blocks (their means and variances averaged), which
makes the block means close to normal and their variance estimates stable.
For every block and channel, z = (mean_a - mean_b) / sqrt(var_a + var_b).
Two complementary tests, combined with a Sidak correction:

- *local*: the largest |z| over all blocks and channels, against the two-sided
  critical value at the Sidak-corrected level (catches a wrong region);
- *global*: per channel, sum of z^2 against chi-square with one degree of
  freedom per block (catches a small bias spread over the whole image).

The estimates are independent across blocks; channels of one render are
correlated (they share paths), hence one global test per channel.

The test trusts the variance estimates.  An estimator that has not yet found
a rare light path in some block reports mean 0 and variance 0 there, which
no z-test can see through; such blocks are counted as *undersampled* in the
report, and the remedy is more samples.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .chi2 import sidak_significance

__all__ = ["ComparisonResult", "compare_estimates"]


@dataclass
class ComparisonResult:
    """Outcome of :func:`compare_estimates`; ``str()`` is the report."""

    passed: bool
    z: np.ndarray            # (blocks_y, blocks_x, channels)
    max_abs_z: float
    critical_z: float
    chi2_p_values: np.ndarray  # per channel
    significance: float        # per sub-test, after the Sidak correction
    block: int
    worst_block: tuple[int, int, int]
    undersampled: int          # block-channels where one estimate is exactly 0 with variance 0 and the other is not

    def __str__(self) -> str:
        verdict = "same image" if self.passed else "DIFFERENT images"
        by, bx, c = self.worst_block
        text = (f"{verdict}: max |z| = {self.max_abs_z:.2f} over {self.z.size} block-channels of {self.block}x"
                f"{self.block} pixels (critical {self.critical_z:.2f}; worst at block row {by}, column {bx}, "
                f"channel {c}); global chi-square p-values per channel "
                f"{', '.join(f'{p:.3g}' for p in self.chi2_p_values)} (significance {self.significance:.3g} each)")
        if self.undersampled:
            text += (f"; {self.undersampled} block-channels look undersampled (one estimate found nothing there): "
                     "render more samples before trusting this verdict")
        return text


def _blocks(image: np.ndarray, block: int) -> np.ndarray:
    h, w, c = image.shape
    h2, w2 = h - h % block, w - w % block
    return image[:h2, :w2].reshape(h2 // block, block, w2 // block, block, c).mean(axis=(1, 3))


def compare_estimates(image_a: np.ndarray, variance_a: np.ndarray, image_b: np.ndarray, variance_b: np.ndarray, *,
                      block: int = 8, alpha: float = 0.01) -> ComparisonResult:
    """Test whether two (H, W, C) estimates with per-pixel variances of the mean agree.

    ``alpha`` is the family-wise false-alarm rate of the whole comparison.
    Pixels outside whole blocks at the right and bottom edges are ignored.
    """
    shapes = {np.shape(x) for x in (image_a, variance_a, image_b, variance_b)}
    if len(shapes) != 1 or len(next(iter(shapes))) != 3:
        raise ValueError(f"images and variances must all have the same (H, W, C) shape, got {sorted(shapes)}")
    if not all(np.all(np.isfinite(x)) for x in (image_a, variance_a, image_b, variance_b)):
        raise ValueError("images and variances must be finite (a pixel with fewer than 2 samples has no variance)")
    h, w, _ = image_a.shape
    if block < 1 or block > min(h, w):
        raise ValueError(f"block must lie in [1, {min(h, w)}], got {block}")
    mean_a, mean_b = _blocks(np.asarray(image_a, np.float64), block), _blocks(np.asarray(image_b, np.float64), block)
    diff = mean_a - mean_b
    # Variance of a block mean: the mean of the pixel variances over block^2 pixels, divided by block^2.
    var_a, var_b = _blocks(np.asarray(variance_a, np.float64), block), _blocks(np.asarray(variance_b, np.float64), block)
    var = (var_a + var_b) / (block * block)
    empty_a, empty_b = (mean_a == 0) & (var_a == 0), (mean_b == 0) & (var_b == 0)
    undersampled = int(np.count_nonzero((empty_a & (mean_b != 0) & (var_b > 0)) |
                                        (empty_b & (mean_a != 0) & (var_a > 0))))
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(var > 0, diff / np.sqrt(var), np.where(diff == 0, 0.0, np.inf))
    channels = z.shape[2]
    significance = sidak_significance(alpha, 1 + channels)
    local_level = sidak_significance(significance, z.size)
    from scipy import stats  # here, not at module level: scipy.stats takes most of a second to import

    critical = float(stats.norm.isf(local_level / 2))
    abs_z = np.abs(z)
    worst = np.unravel_index(np.argmax(abs_z), z.shape)
    finite = np.isfinite(z)
    chi2_p = np.array([stats.chi2.sf(np.sum(z[..., c][finite[..., c]] ** 2), max(int(finite[..., c].sum()), 1))
                       if np.all(finite[..., c]) else 0.0 for c in range(channels)])
    passed = bool(abs_z.max() < critical and np.all(chi2_p >= significance))
    return ComparisonResult(passed, z, float(abs_z.max()), critical, chi2_p, significance, block,
                            tuple(int(i) for i in worst), undersampled)
