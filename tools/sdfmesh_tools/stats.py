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


# ---------------------------------------------------------------------------------------
# The verdict per class: ratios best-SDF / best-mesh with inputs and replicates


def _t_quantile(p: float, df: int) -> float:
    from scipy.stats import t

    return float(t.ppf(p, df))


def ratio_ci(logs_by_input: dict, alpha: float = 0.05) -> dict:
    """Geometric-mean ratio over inputs, and its (1 - alpha) t-interval.

    `logs_by_input` maps each input to the list of log ratios of its replicates (one value
    per separate process). Each input's mean log ratio is one observation; with 2 or more
    inputs the interval is a t-interval over those means (df = inputs - 1), which holds both
    the spread between inputs and the run-to-run noise (each input's mean carries its
    replicates' noise divided by their number). With one input the interval is a t-interval
    over its replicates: run-to-run noise only (`unit` says which).

    Returns a dict: ratio, lo, hi (None where no interval exists), n_inputs, n_runs, unit,
    run_spread (exp of the pooled within-input standard deviation of log ratios: the
    run-to-run factor; None without replicates), within_noise (lo <= 1 <= hi; None without
    an interval).
    """
    means, resid, n_runs = [], [], 0
    for logs in logs_by_input.values():
        v = [float(x) for x in logs if x is not None and np.isfinite(x)]
        if not v:
            continue
        means.append(float(np.mean(v)))
        resid += [x - means[-1] for x in v]
        n_runs += len(v)
    out = {"ratio": None, "lo": None, "hi": None, "n_inputs": len(means), "n_runs": n_runs,
           "unit": None, "run_spread": None, "within_noise": None}
    if not means:
        return out
    dof_within = n_runs - len(means)
    if dof_within > 0:
        out["run_spread"] = float(np.exp(np.sqrt(np.sum(np.square(resid)) / dof_within)))
    m = float(np.mean(means))
    out["ratio"] = float(np.exp(m))
    if len(means) >= 2:
        sample, out["unit"] = np.asarray(means), "inputs"
    else:
        only = [float(x) for x in next(v for v in logs_by_input.values() if v)]
        sample, out["unit"] = np.asarray(only), "runs"
    n = sample.size
    if n < 2:
        return out
    se = float(np.std(sample, ddof=1) / np.sqrt(n))
    h = _t_quantile(1 - alpha / 2, n - 1) * se
    out["lo"], out["hi"] = float(np.exp(m - h)), float(np.exp(m + h))
    out["within_noise"] = out["lo"] <= 1.0 <= out["hi"]
    return out


def crossovers(xs, winners) -> list[tuple]:
    """Where the winner changes along a family: [(x_before, x_after, old, new)].

    `xs` ascending, `winners` the winner at each x (None where there is none: skipped)."""
    out, prev = [], None
    for x, w in zip(xs, winners):
        if w is None:
            continue
        if prev is not None and w != prev[1]:
            out.append((prev[0], x, prev[1], w))
        prev = (x, w)
    return out


# ---------------------------------------------------------------------------------------
# Cost model


def fit_linear(X, y, relative: bool = False, nonneg: bool = False):
    """Least-squares coefficients of y ~ X (X already holds a column of ones for the
    constant). `relative`: minimise the squared relative error (each equation divided by
    its y > 0), so that the slowest runs do not decide the fit alone; `nonneg`: every
    coefficient >= 0 (scipy's NNLS). Returns the coefficient vector."""
    X = np.asarray(X, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if relative:
        w = 1.0 / y
        X, y = X * w[:, None], y * w
    # columns scaled to a largest magnitude of 1, so counts in the millions and the constant
    # are conditioned alike
    scale = np.max(np.abs(X), axis=0)
    scale[scale == 0] = 1.0
    if nonneg:
        from scipy.optimize import nnls

        coef, _ = nnls(X / scale, y)
    else:
        coef, *_ = np.linalg.lstsq(X / scale, y, rcond=None)
    return coef / scale


def relative_errors(pred, y):
    """|pred - y| / y for y > 0."""
    pred = np.asarray(pred, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    ok = y > 0
    return np.abs(pred[ok] - y[ok]) / y[ok]
