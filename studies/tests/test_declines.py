"""`declines`: the race_scale studies' reading of a run that learns the race and then loses it
(studies/race_scale_2m's README), shared by race_scale_2m and race_scale_rollout_2m."""

from __future__ import annotations

import math

from studies.lib.common import declines


def curve(successes_per_window: list[float]) -> list[list[float]]:
    """One iteration per 62,500 env steps, two per 125k window, at these training successes."""
    rows = []
    for i, s in enumerate(successes_per_window):
        rows += [[125_000 * i + 62_500, s, 0.0], [125_000 * (i + 1), s, 0.0]]
    return rows


def test_a_run_that_peaks_and_ends_low_declines_and_one_that_holds_does_not() -> None:
    low_end = [0.1] * 3 + [0.7] * 5 + [0.3] * 8
    assert declines(curve(low_end))
    assert not declines(curve([0.1] * 3 + [0.7] * 13))  # holds
    assert not declines(curve([0.5] * 15 + [0.1]))  # never peaked
    assert not declines(curve(low_end[:-1] + [0.4]))  # ends at the low mark: not below it


def test_iterations_without_a_finished_race_are_left_out() -> None:
    # the only finite value is 0.5 (no peak); the last window has none, read as 0
    rows = [[1_000, math.nan, 0.0], [2_000, 0.5, 0.0], [130_000, math.nan, 0.0]]
    assert not declines(rows)
    assert declines(rows, peak=0.5)


def test_other_windows_and_marks() -> None:
    rows = [[50, 0.9, 0.0], [100, 0.9, 0.0], [150, 0.2, 0.0], [200, 0.2, 0.0]]
    assert declines(rows, window=100, stop=200)
    assert not declines(rows, window=100, stop=200, low=0.1)
    assert not declines(rows, window=200, stop=200)  # one window: mean 0.55, no peak
