"""studies.lib.compare: its tables and CLI, on the statistics of rllib_asor.report.paired (the\nunpaired bootstrap CI of Δ and one-sided Mann–Whitney p, the paired BCa interval)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from rllib_asor.report.paired import unpaired_difference as compare
from rllib_asor.report.stats import bootstrap_ci
from studies.lib.compare import compare_paired, main, metric_value


def test_pairing_by_seed_removes_the_shared_seed_luck() -> None:
    # Seeds differ a lot (shared luck); the treatment is +0.05 on every seed but one.
    base = {0: 0.1, 1: 0.9, 2: 0.5, 3: 0.3, 4: 0.7, 5: 0.2, "x": 1.0}
    treat = {0: 0.15, 1: 0.95, 2: 0.55, 3: 0.35, 4: 0.75, 5: 0.24, 9: 0.0}
    c = compare_paired(base, treat)
    assert c["n_pairs"] == 6  # seeds "x" and 9 are run by one method only
    assert c["diff"] == pytest.approx((0.05 * 5 + 0.04) / 6)
    assert 0 < c["ci_low"] <= c["diff"] <= c["ci_high"] < 0.06
    assert c["p_value"] < 0.05
    unpaired = compare([base[s] for s in range(6)], [treat[s] for s in range(6)], n_resamples=999)
    assert unpaired["ci_low"] < 0 < unpaired["ci_high"]


def test_paired_identical_runs_and_no_common_seed() -> None:
    c = compare_paired({0: 1.0, 1: 2.0}, {0: 1.0, 1: 2.0})
    assert c["diff"] == c["ci_low"] == c["ci_high"] == 0.0 and c["p_value"] == 1.0
    with pytest.raises(ValueError, match="at least one seed"):
        compare_paired({0: 1.0}, {1: 1.0})


def test_paired_interval_is_the_projects_interval_of_the_differences() -> None:
    base = {s: v for s, v in enumerate([0.2, 0.0, 0.7, 0.9, 0.1, 0.6, 0.3, 0.8])}
    treat = {s: v for s, v in enumerate([0.5, 0.1, 0.6, 0.9, 0.0, 0.8, 0.7, 0.6])}
    c = compare_paired(base, treat)
    diffs = [treat[s] - base[s] for s in base]
    assert (c["ci_low"], c["ci_high"]) == bootstrap_ci(diffs)
    one = compare_paired({0: 0.2}, {0: 0.5})  # one pair: no spread to resample
    assert one["diff"] == pytest.approx(0.3) and math.isnan(one["ci_low"])


def test_metric_value_dotted_and_wildcard() -> None:
    run = {"eval": {"per_map": {"0": {"success": 1.0}, "1": {"success": 0.0}}}, "ok": True}
    assert metric_value(run, "eval.per_map.*.success") == 0.5
    assert metric_value(run, "eval.per_map.1.success") == 0.0
    assert metric_value(run, "ok") == 1.0


def test_cli_table(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    runs = tmp_path / "lava" / "runs"
    runs.mkdir(parents=True)
    values = {"ppo": [0.6, 0.7, 0.65], "asor": [0.8, 0.85, 0.9], "asor-paper": [0.6, 0.6, 0.6]}
    for method, vs in values.items():
        for seed, v in enumerate(vs):
            run = {"method": method, "seed": seed, "greedy_return_mean": v}
            (runs / f"{method}-{seed}.json").write_text(json.dumps(run))
    out = tmp_path / "table.md"
    argv = ["--runs", str(tmp_path / "lava"), "--metric", "greedy_return_mean"]
    assert (
        main([*argv, "--baseline", "ppo", "--methods", "asor", "asor-paper", "--out", str(out)])
        == 0
    )
    printed = capsys.readouterr().out
    for name in ("ppo (baseline)", "| asor |", "| asor-paper |", "Mann–Whitney"):
        assert name in printed
    assert out.read_text() in printed
    assert "nan" not in printed


def test_cli_paired_table(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    runs = tmp_path / "hopper" / "runs"
    runs.mkdir(parents=True)
    for method, vs in {"ppo": [600.0, 700.0, 500.0], "asor": [610.0, 720.0, 505.0]}.items():
        for seed, v in enumerate(vs):
            run = {"method": method, "seed": seed, "eval_mean": v}
            (runs / f"{method}-{seed}.json").write_text(json.dumps(run))
    argv = ["--runs", str(tmp_path / "hopper"), "--metric", "eval_mean", "--paired"]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "paired by seed" in printed and "Wilcoxon" in printed
    assert "| asor | 3 | 600.000 ± 100.000 | 611.667 ± 107.510 | +11.667 |" in printed


def test_the_lava_tables_use_the_reports_bootstrap_ci() -> None:
    """One interval for `rllib report` and the studies' tables (one implementation)."""
    import studies.lib.lava_reproduction as lava

    assert lava.bootstrap_ci is bootstrap_ci
