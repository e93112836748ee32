"""Curves on a grid every seed reached (no endpoint resting on fewer seeds), and the figures
`rllib compare` / `rllib ab` write."""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

from rllib_asor.report import plots, render, summary
from rllib_asor.report.paired import paired_difference
from rllib_asor.report.results import find_trials
from rllib_asor.report.stats import bootstrap_ci, bootstrap_ci_columns
from tests.report.helpers import write_trial


def assert_png(path: Path) -> None:
    img = matplotlib.image.imread(path)
    assert img.ndim == 3 and img.shape[0] > 100 and img.shape[1] > 100


def test_common_grid_ends_where_the_shortest_seed_ends(tmp_path: Path) -> None:
    params = {"env": "E", "rllib_asor_run": "PPO"}
    write_trial(tmp_path, "s0", {**params, "seed": 0}, [0.0, 10.0, 20.0, 30.0])  # to 4,000 steps
    write_trial(tmp_path, "s1", {**params, "seed": 1}, [0.0, 20.0])  # to 2,000 steps
    trials = sorted(find_trials(tmp_path), key=lambda t: t.path.name)
    grid, ys = plots.common_grid(trials, "env_runners/episode_return_mean", summary.DEFAULT_X)
    assert grid[0] == 1000 and grid[-1] == 2000  # never beyond what both seeds reached
    assert ys.shape == (2, plots.GRID_POINTS) and np.isfinite(ys).all()
    np.testing.assert_allclose(ys[:, -1], [10.0, 20.0])  # both seeds at the last point
    write_trial(tmp_path, "late", {**params, "seed": 2}, [1.0], steps_per_iter=9000)
    grid, _ = plots.common_grid(find_trials(tmp_path), "env_runners/episode_return_mean",
                                summary.DEFAULT_X)  # fmt: skip
    assert grid.size == 0  # no range shared by all three seeds: no curve rather than a wrong one


def test_band_is_the_projects_bca_interval_per_grid_point() -> None:
    ys = np.array([[1.0, 5.0, 2.0], [2.0, 5.0, 9.0], [4.0, 5.0, 3.0], [3.0, 5.0, 7.0]])
    lo, hi = bootstrap_ci_columns(ys)
    assert (lo[1], hi[1]) == (5.0, 5.0)  # constant column
    for j in (0, 2):
        assert (lo[j], hi[j]) == pytest.approx(bootstrap_ci(ys[:, j]))


def test_report_curves_and_symlinked_folders(tmp_path: Path) -> None:
    real = tmp_path / "real"
    for s in range(3):
        write_trial(real / "exp", f"PPO_{s}", {"env": "E", "seed": s, "rllib_asor_run": "PPO"},
                    [0.0, 5.0 * s, 10.0], steps_per_iter=1000 * (s + 1))  # fmt: skip
    (tmp_path / "view").mkdir()
    os.symlink(real / "exp", tmp_path / "view" / "exp")
    md = render.make_report(tmp_path / "view", tmp_path / "out").read_text()
    assert "| PPO | 3 |" in md
    assert_png(tmp_path / "out" / "curves_E.png")


def test_paired_and_dynamics_figures(tmp_path: Path) -> None:
    base = {0: 1.0, 1: 4.0, 2: 2.0}
    r = paired_difference(base, {0: 2.0, 1: 3.0, 2: 5.0}, baseline_name="PPO",
                          treatment_name="PPO+ASOR")  # fmt: skip
    plots.plot_paired(r, tmp_path / "paired.png")
    assert_png(tmp_path / "paired.png")
    rows = []
    for did in ("0", "1"):
        d = paired_difference(base, {k: v + 1 for k, v in base.items()}, baseline_name="PPO",
                              treatment_name="PPO+ASOR")  # fmt: skip
        d.dynamics = did
        rows.append(d)
    plots.plot_dynamics(rows, tmp_path / "dyn.png")
    assert_png(tmp_path / "dyn.png")
