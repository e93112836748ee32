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
