"""studies/race_scale_2m's reading beside its rule: which runs declined (README.md)."""

from __future__ import annotations

import math

from studies.race_scale_2m.summarise import declines, windows


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
    assert not declines(curve(low_end[:-1] + [0.4]))  # ends at LOW: not below it


def test_windows_leave_out_iterations_without_a_finished_race() -> None:
    rows = [[1_000, math.nan, 0.0], [2_000, 0.5, 0.0], [130_000, math.nan, 0.0]]
    w = windows(rows)
    assert len(w) == 16 and w[0] == 0.5 and w[1] is None
    assert not declines(rows)
