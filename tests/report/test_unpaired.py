"""`rllib_asor.report.paired`'s other comparisons, used by the studies' tables: the unpaired
one (every run, seeds pooled: percentile bootstrap of Δ, one-sided Mann–Whitney p) and the other
intervals beside the paired BCa one."""

from __future__ import annotations

import math

import pytest

from rllib_asor.report.paired import other_intervals
from rllib_asor.report.paired import unpaired_difference as compare


def test_clearly_better_treatment() -> None:
    c = compare([0.1, 0.2, 0.15, 0.12, 0.18], [0.8, 0.9, 0.85, 0.82, 0.88], n_resamples=999)
    assert c["diff"] == pytest.approx(0.7)
    assert 0 < c["ci_low"] <= c["diff"] <= c["ci_high"]
    assert c["p_value"] < 0.05
    assert c["n_baseline"] == c["n_treatment"] == 5


def test_identical_constant_samples_are_degenerate_not_nan() -> None:
    c = compare([0.635] * 5, [0.635] * 5)
    assert c["diff"] == 0.0 and c["ci_low"] == 0.0 and c["ci_high"] == 0.0
    assert c["p_value"] >= 0.5
    assert c["std_baseline"] == 0.0
    assert not any(math.isnan(v) for v in c.values())


def test_one_constant_or_single_sample() -> None:
    c = compare([0.5], [0.6, 0.7, 0.8], n_resamples=999)
    assert 0.1 - 1e-9 <= c["ci_low"] <= c["ci_high"] <= 0.3 + 1e-9
    c = compare([0.6, 0.7, 0.8], [0.5, 0.5, 0.5], n_resamples=999)
    assert -0.3 - 1e-9 <= c["ci_low"] <= c["ci_high"] <= -0.1 + 1e-9
    assert c["p_value"] > 0.5


def test_pairing_narrows_the_interval_when_seeds_share_their_luck() -> None:
    base = {0: 0.1, 1: 0.9, 2: 0.5, 3: 0.3, 4: 0.7, 5: 0.2}
    treat = {s: v + (0.05 if s != 5 else 0.04) for s, v in base.items()}
    i = other_intervals(base, treat)
    for name in ("paired_percentile", "paired_t"):
        lo, hi = i[name]
        assert 0 < lo <= hi < 0.06, name
    lo, hi = i["unpaired"]
    assert lo < 0 < hi
