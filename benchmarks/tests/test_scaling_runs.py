"""`benchmarks.scaling`'s Ray parts run end to end on this machine (slow: about a minute each):
they broke once unnoticed when ASOR's code they time moved, and `make gpu-check` found out on
the GPU node. Covered in `make test` only by the argument and summary tests
(test_scaling_args.py)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks import scaling


def _scaling(out: Path, *argv: str) -> dict:
    """`benchmarks.scaling --quick --runners 1 --iters 1 ARGV` into `out`: its scaling.json."""
    assert (
        scaling.main(["--quick", "--runners", "1", "--iters", "1", *argv, "--out", str(out)]) == 0
    )
    return json.loads((out / "scaling.json").read_text())


@pytest.mark.slow
def test_the_split_times_asors_piece_inside_an_iteration(tmp_path: Path) -> None:
    [split] = _scaling(tmp_path, "--sync-runners", "1", "--parts", "split")["split"]
    assert split["iterations"]["asor"] and split["iterations"]["ppo"]
    for it in split["iterations"]["asor"]:
        assert it["asor_piece"] > 0 and it["asor_rank"] > 0 and it["asor_learn"] > 0
        assert it["asor_batch"] + it["asor_rank"] + it["asor_learn"] <= it["asor_piece"] * 1.05
    for it in split["iterations"]["ppo"]:
        assert it["asor_piece"] == 0 and it["asor_learn"] == 0


@pytest.mark.slow
def test_overlapped_end_to_end_runs_with_asor(tmp_path: Path) -> None:
    [row] = _scaling(tmp_path, "--algos", "asor_overlap", "--parts", "e2e")["rows"]
    assert row["algo"] == "asor_overlap" and row["e2e"] > 0


@pytest.mark.slow
def test_sampling_reports_the_median_and_the_slowest_runner_per_call(tmp_path: Path) -> None:
    [row] = _scaling(tmp_path, "--algos", "ppo", "--runners", "2", "--parts", "sample")["rows"]
    assert row["sample"] > 0
    assert 0 < row["sample_runner_median_s"] <= row["sample_runner_max_s"] <= row["sample_call_s"]
