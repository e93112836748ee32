"""`rllib evaluate DIR --all-checkpoints [--best-by NAME]`: every checkpoint of every trial,
oldest first, and each trial's best beside its newest (the decision a run that declined needs).
The Ray end-to-end run is in tests/cli/test_e2e.py."""

from __future__ import annotations

from pathlib import Path

import pytest

from rllib_asor.cli import evaluate
from rllib_asor.cli.errors import UsageError
from rllib_asor.cli.main import main


def checkpoint(trial: Path, number: int) -> str:
    path = trial / f"checkpoint_{number:06d}"
    path.mkdir(parents=True)
    (path / evaluate.CHECKPOINT_MARKER).write_text("{}")
    return str(path)


def stats(path: str, ret: float, **metrics: float) -> dict:
    return {"checkpoint": path, "return_mean": ret, "return_min": ret - 1, "return_max": ret + 1,
            "episode_metrics": metrics}  # fmt: skip


def test_every_checkpoint_trial_by_trial_in_the_order_they_were_written(tmp_path: Path) -> None:
    b = [checkpoint(tmp_path / "exp/trial_b", n) for n in (10, 2)]
    a = [checkpoint(tmp_path / "exp/trial_a", n) for n in (100, 9)]
    assert evaluate.every_checkpoint(str(tmp_path / "exp")) == [a[1], a[0], b[1], b[0]]
    assert evaluate.every_checkpoint(a[0]) == [a[0]]
    (tmp_path / "empty").mkdir()
    with pytest.raises(UsageError, match="no RLlib checkpoint in this directory"):
        evaluate.every_checkpoint(str(tmp_path / "empty"))


def test_the_best_checkpoint_per_trial_beside_its_newest() -> None:
    runs = [
        stats("/e/t1/checkpoint_000001", 1.0, success=0.2),
        stats("/e/t1/checkpoint_000002", 3.0, success=0.7),
        stats("/e/t1/checkpoint_000003", 2.0, success=0.7),  # a tie: the newer one wins
        stats("/e/t2/checkpoint_000001", 5.0, success=0.1),
    ]
    by_success, by_return = (
        evaluate.best_per_trial(runs, "success"),
        evaluate.best_per_trial(runs, "return_mean"),
    )
    assert [(b["trial"], b["best"], b["best_value"]) for b in by_success] == [
        ("/e/t1", "/e/t1/checkpoint_000003", 0.7), ("/e/t2", "/e/t2/checkpoint_000001", 0.1)
    ]  # fmt: skip
    assert by_return[0]["best"] == "/e/t1/checkpoint_000002" and by_return[0]["best_value"] == 3.0
    assert (
        by_return[0]["newest"] == "/e/t1/checkpoint_000003" and by_return[0]["newest_value"] == 2.0
    )


def test_best_by_a_number_the_evaluation_lacks_names_what_is_allowed() -> None:
    assert evaluate.score(stats("c", 1.5, success=0.25), "return_min") == 0.5
    assert evaluate.score(stats("c", 1.5, success=0.25), "success") == 0.25
    with pytest.raises(
        UsageError,
        match=r"'sucess' is not a number .*allowed: return_mean, return_min, return_max, success$",
    ):
        evaluate.score(stats("c", 1.5, success=0.25), "sucess")


def test_best_by_without_all_checkpoints_is_one_line_and_exit_2(tmp_path: Path, capsys) -> None:
    path = checkpoint(tmp_path / "trial", 1)
    assert main(["evaluate", path, "--best-by", "success"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["rllib evaluate: error: --best-by: is only read with --all-checkpoints"], err


def test_without_the_flag_each_trials_newest_checkpoint_by_time(tmp_path: Path) -> None:
    import os

    a = [checkpoint(tmp_path / "exp/trial_a", n) for n in (1, 2)]
    b = [checkpoint(tmp_path / "exp/trial_b", n) for n in (1, 2)]
    os.utime(a[0], (2e9, 2e9))  # trial_a's checkpoint_000001 written last
    assert evaluate.trial_checkpoints(str(tmp_path / "exp")) == [a[0], b[1]]
    assert evaluate.trial_checkpoints(str(tmp_path / "exp/trial_b")) == [b[1]]
    assert evaluate.find_checkpoint(str(tmp_path / "exp/trial_a")) == a[0]
