"""The ESCP study's summariser applies the rule's validity bar before any verdict."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def summarise(runs: Path) -> dict:
    path = ROOT / "benchmarks/studies/escp_walker/summarise.py"
    spec = importlib.util.spec_from_file_location("escp_study_summarise", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.summarise(runs)


def write(runs: Path, method: str, seed: int, stationary: float) -> None:
    run = {"method": method, "seed": seed, "eval": {"stationary": stationary, "ns": stationary}}
    (runs / f"{method}-{seed}.json").write_text(json.dumps(run))


def test_validity_bar_waits_for_all_escp_seeds_then_decides(tmp_path: Path) -> None:
    for seed in range(4):
        write(tmp_path, "escp", seed, 2000.0)
    assert summarise(tmp_path)["answer"].startswith("pending")
    write(tmp_path, "escp", 4, 2000.0)
    assert summarise(tmp_path)["answer"].startswith("valid")
    write(tmp_path, "escp", 4, 0.0)  # mean 1,600: still learns
    assert summarise(tmp_path)["escp_learns"]
    for seed in range(5):
        write(tmp_path, "escp", seed, 999.0)
    res = summarise(tmp_path)
    assert not res["escp_learns"] and res["answer"].startswith("budget too small")


def test_gain_needs_five_pairs_an_interval_above_zero_and_five_percent(tmp_path: Path) -> None:
    for seed in range(5):
        write(tmp_path, "escp", seed, 1000.0 + 10 * seed)
        write(tmp_path, "escp_asor", seed, 1100.0 + 12 * seed)  # +100 … +108: > 5 % of ~1,020
    rows = {(c["treatment"], c["metric"]): c["rule"] for c in summarise(tmp_path)["comparisons"]}
    assert rows[("escp_asor", "stationary")] == "gain"
    for seed in range(5):
        write(tmp_path, "escp_asor", seed, 1010.0 + 10 * seed + seed % 2)  # +10/+11: under 5 %
    rows = {(c["treatment"], c["metric"]): c["rule"] for c in summarise(tmp_path)["comparisons"]}
    assert rows[("escp_asor", "stationary")] == "no detectable difference"
