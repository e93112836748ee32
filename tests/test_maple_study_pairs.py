"""The MAPLE study's summariser pairs runs only when they trained on the same rows."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def summarise_module():
    path = ROOT / "benchmarks/studies/maple_hopper/summarise.py"
    spec = importlib.util.spec_from_file_location("maple_study_summarise", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def write_run(runs: Path, method: str, seed: int, fingerprint: str, score: float) -> None:
    run = {"dataset": "medium", "method": method, "seed": seed, "score": score}
    run["data_fingerprint"] = fingerprint
    (runs / f"medium-{method}-{seed}.json").write_text(json.dumps(run))


def test_seeds_from_different_data_builds_still_pair(tmp_path: Path) -> None:
    for seed, fp in [(0, "aaaa"), (1, "bbbb")]:
        write_run(tmp_path, "maple", seed, fp, 50.0 + seed)
        write_run(tmp_path, "maple_asor_paper", seed, fp, 40.0 + seed)
    data = summarise_module().load(tmp_path)
    assert sorted(data[("medium", "maple")]) == [0, 1]
    assert data[("medium", "maple_asor_paper")][1]["score"] == 41.0


def test_a_pair_from_two_data_builds_is_refused(tmp_path: Path) -> None:
    write_run(tmp_path, "maple", 0, "aaaa", 50.0)
    write_run(tmp_path, "maple_asor_paper", 0, "bbbb", 40.0)
    with pytest.raises(SystemExit, match=r"medium/0.*aaaa.*bbbb"):
        summarise_module().load(tmp_path)
