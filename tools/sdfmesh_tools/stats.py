"""Statistics for the hypothesis test: ratio of medians with a bootstrap CI, Mann-Whitney U."""

from __future__ import annotations

import numpy as np


def ratio_of_medians_ci(a, b, n_boot: int = 4000, alpha: float = 0.05, seed: int = 12345):
    """median(a) / median(b) and a percentile bootstrap (1 - alpha) interval.

    a and b are resampled independently with replacement. Returns (ratio, low, high);
    low and high are None when either sample has fewer than 2 values.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.size == 0 or b.size == 0:
        raise ValueError("empty sample")
    ratio = float(np.median(a) / np.median(b))
    if a.size < 2 or b.size < 2:
        return ratio, None, None
    rng = np.random.default_rng(seed)
    ma = np.median(a[rng.integers(0, a.size, (n_boot, a.size))], axis=1)
    mb = np.median(b[rng.integers(0, b.size, (n_boot, b.size))], axis=1)
    boots = ma / mb
    lo, hi = np.quantile(boots, [alpha / 2, 1 - alpha / 2])
    return ratio, float(lo), float(hi)


def mann_whitney_p(a, b) -> float | None:
    """Two-sided Mann-Whitney U p-value (None when a sample is empty or scipy is missing)."""
    if len(a) == 0 or len(b) == 0:
        return None
    try:
        from scipy.stats import mannwhitneyu
    except ImportError:
        return None
    return float(mannwhitneyu(a, b, alternative="two-sided").pvalue)
