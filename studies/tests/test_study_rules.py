"""The studies' summarisers apply their committed rules: the MAPLE study pairs runs only when
they trained on the same rows; the ESCP study decides its validity bar before any verdict."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


def study_script(study: str, script: str = "summarise"):
    """studies/<study>/<script>.py as a module (a study folder is not a package)."""
    path = ROOT / f"studies/{study}/{script}.py"
    spec = importlib.util.spec_from_file_location(f"{study}_{script}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# ------------------------------------------------------------------ MAPLE: pairs share their rows
def write_run(runs: Path, method: str, seed: int, fingerprint: str, score: float) -> None:
    run = {"dataset": "medium", "method": method, "seed": seed, "score": score}
    run["data_fingerprint"] = fingerprint
    (runs / f"medium-{method}-{seed}.json").write_text(json.dumps(run))


def test_seeds_from_different_data_builds_still_pair(tmp_path: Path) -> None:
    for seed, fp in [(0, "aaaa"), (1, "bbbb")]:
        write_run(tmp_path, "maple", seed, fp, 50.0 + seed)
        write_run(tmp_path, "maple_asor_paper", seed, fp, 40.0 + seed)
    data = study_script("maple_hopper").load(tmp_path)
    assert sorted(data[("medium", "maple")]) == [0, 1]
    assert data[("medium", "maple_asor_paper")][1]["score"] == 41.0


def test_a_pair_from_two_data_builds_is_refused(tmp_path: Path) -> None:
    write_run(tmp_path, "maple", 0, "aaaa", 50.0)
    write_run(tmp_path, "maple_asor_paper", 0, "bbbb", 40.0)
    with pytest.raises(SystemExit, match=r"medium/0.*aaaa.*bbbb"):
        study_script("maple_hopper").load(tmp_path)


def test_late_score_averages_the_second_half_of_the_curve_only() -> None:
    curve = [{"iteration": i, "score": float(i)} for i in (5, 10, 15, 20)]
    late = study_script("maple_hopper").late_score
    assert late({"iters": 20, "curve": curve}) == 17.5  # iterations 15 and 20, not 10
    assert np.isnan(late({"iters": 20, "curve": curve[:2]}))  # nothing after half: no value
    gaps = [*curve, {"iteration": 16, "score": float("nan")}]  # the first runs' NaN points
    assert late({"iters": 20, "curve": gaps}) == 17.5


def test_a_comparison_short_of_its_planned_pairs_is_interim(tmp_path: Path) -> None:
    summarise = study_script("maple_hopper")
    for seed, gain in enumerate([1.0, 20.0, 25.0, 130.0, 3.0]):  # every Δ positive
        write_run(tmp_path, "maple", seed, "aaaa", 50.0)
        write_run(tmp_path, "maple_asor", seed, "aaaa", 50.0 + gain)
        data = summarise.load(tmp_path)
        verdict = summarise.paired(data, "maple_asor", "maple", planned=5)["verdict"]
        if seed < 2:
            assert verdict == "not enough pairs"
        elif seed < 4:  # the interval is above 0, but on fewer pairs than planned
            assert verdict == f"interim, {seed + 1} of 5 pairs: reproduced (interval above 0)"
        else:
            assert verdict == "reproduced (interval above 0)"


def test_the_runner_skips_a_seed_whose_runs_used_other_data(tmp_path: Path) -> None:
    run = study_script("maple_hopper", "run")
    write_run(tmp_path, "maple", 0, "old", 50.0)
    write_run(tmp_path, "maple", 1, "new", 50.0)
    assert run.runs_on_other_data(tmp_path, "medium", 0, "new") == ["medium-maple-0.json"]
    assert run.runs_on_other_data(tmp_path, "medium", 1, "new") == []
    assert run.runs_on_other_data(tmp_path, "random", 0, "new") == []


# ------------------------------------------------------- ESCP: the validity bar, then the rule
def escp_summary(runs: Path) -> dict:
    return study_script("escp_walker").summarise(runs)


def write_escp_run(runs: Path, method: str, seed: int, stationary: float) -> None:
    run = {"method": method, "seed": seed, "eval": {"stationary": stationary, "ns": stationary}}
    (runs / f"{method}-{seed}.json").write_text(json.dumps(run))


def test_validity_bar_waits_for_all_escp_seeds_then_decides(tmp_path: Path) -> None:
    for seed in range(4):
        write_escp_run(tmp_path, "escp", seed, 2000.0)
    assert escp_summary(tmp_path)["answer"].startswith("pending")
    write_escp_run(tmp_path, "escp", 4, 2000.0)
    assert escp_summary(tmp_path)["answer"].startswith("valid")
    write_escp_run(tmp_path, "escp", 4, 0.0)  # mean 1,600: still learns
    assert escp_summary(tmp_path)["escp_learns"]
    for seed in range(5):
        write_escp_run(tmp_path, "escp", seed, 999.0)
    res = escp_summary(tmp_path)
    assert not res["escp_learns"] and res["answer"].startswith("budget too small")


def test_gain_needs_five_pairs_an_interval_above_zero_and_five_percent(tmp_path: Path) -> None:
    for seed in range(5):
        write_escp_run(tmp_path, "escp", seed, 1000.0 + 10 * seed)
        # differences +100 … +108: above 5 % of ESCP's ~1,020
        write_escp_run(tmp_path, "escp_asor", seed, 1100.0 + 12 * seed)
    rows = {(c["treatment"], c["metric"]): c["rule"] for c in escp_summary(tmp_path)["comparisons"]}
    assert rows[("escp_asor", "stationary")] == "gain"
    for seed in range(5):
        # differences +10 / +11: above 0, under 5 %
        write_escp_run(tmp_path, "escp_asor", seed, 1010.0 + 10 * seed + seed % 2)
    rows = {(c["treatment"], c["metric"]): c["rule"] for c in escp_summary(tmp_path)["comparisons"]}
    assert rows[("escp_asor", "stationary")] == "no detectable difference"


def test_cql_hopper_paired_verdict_is_the_rules():
    from studies.lib.offline_cql import paired_verdict

    assert paired_verdict([21.2, 3.6, 27.8]) == "better"  # mean ≥ 5, every seed > 0
    assert paired_verdict([30.0, 30.0, -0.1]) == "no clear difference at this budget"
    assert paired_verdict([4.0, 5.0, 5.0]) == "no clear difference at this budget"  # mean < 5
    assert paired_verdict([-5.0, -6.0, -4.0]) == "worse"
