"""Statistics over per-seed final values: the one bootstrap interval every table uses."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

BOOTSTRAP_RESAMPLES = 5000


def bootstrap_ci(values: Sequence[float], confidence: float = 0.95) -> tuple[float, float]:
    """BCa bootstrap interval of the mean (scipy, 5,000 resamples, seed 0: reproducible).

    NaN for fewer than two values (no spread to resample); (v, v) for a constant sample.
    """
    from scipy.stats import bootstrap

    arr = np.asarray(values, dtype=float)
    if arr.size < 2:
        return math.nan, math.nan
    if np.allclose(arr, arr[0]):
        return float(arr.mean()), float(arr.mean())
    res = bootstrap(
        (arr,), np.mean, confidence_level=confidence, n_resamples=BOOTSTRAP_RESAMPLES, rng=0
    )
    return float(res.confidence_interval.low), float(res.confidence_interval.high)


def iqm(values: Sequence[float]) -> float:
    """Interquartile mean: mean of the middle 50% (scipy's trim_mean with 0.25 cut)."""
    from scipy.stats import trim_mean

    return float(trim_mean(np.asarray(values, dtype=float), 0.25))


def mean_std(values: Sequence[float]) -> tuple[float, float]:
    """Mean and sample std (ddof 1; 0 for one value) of the finite values; NaNs if none."""
    arr = np.asarray([v for v in values if math.isfinite(v)], dtype=float)
    if arr.size == 0:
        return math.nan, math.nan
    return float(arr.mean()), float(arr.std(ddof=1)) if arr.size > 1 else 0.0


def bootstrap_ci_columns(
    values: np.ndarray, confidence: float = 0.95
) -> tuple[np.ndarray, np.ndarray]:
    """`bootstrap_ci` of each column's mean (rows = seeds), in one vectorised scipy call.

    A constant column gets (v, v); fewer than two rows gives NaNs.
    """
    import warnings

    from scipy.stats import bootstrap

    arr = np.asarray(values, dtype=float)
    mean = arr.mean(axis=0)
    if arr.shape[0] < 2:
        return np.full_like(mean, np.nan), np.full_like(mean, np.nan)
    with warnings.catch_warnings():  # constant columns: BCa is undefined there (NaN, handled)
        warnings.simplefilter("ignore")
        res = bootstrap(
            (arr,),
            np.mean,
            axis=0,
            confidence_level=confidence,
            n_resamples=BOOTSTRAP_RESAMPLES,
            rng=0,
        )
    lo, hi = res.confidence_interval.low, res.confidence_interval.high
    const = np.all(np.isclose(arr, arr[0]), axis=0)
    return np.where(const | ~np.isfinite(lo), mean, lo), np.where(
        const | ~np.isfinite(hi), mean, hi
    )
