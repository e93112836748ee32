"""The studies' unfinished-run saves (studies.lib.common.save_partial / load_partial): a run
killed at any moment of a save resumes from a complete checkpoint, never a half-written one."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from studies.lib.common import load_partial, save_partial


def write_checkpoint(step: int):
    """A save callable that writes two files, as a checkpoint plus a replay pickle would."""

    def save(folder: Path) -> None:
        (folder / "weights").write_text(f"weights {step}")
        (folder / "replay").write_text(f"replay {step}")

    return save


def checkpoint_contents(folder: Path) -> tuple[str, str]:
    return (folder / "weights").read_text(), (folder / "replay").read_text()


def test_nothing_saved_loads_as_none(tmp_path: Path) -> None:
    assert load_partial(tmp_path / "run.partial") is None


def test_each_save_is_loaded_with_its_own_checkpoint_and_only_one_checkpoint_is_kept(
    tmp_path: Path,
) -> None:
    partial = tmp_path / "run.partial"
    for step in range(1, 5):
        save_partial(partial, {"iteration": step}, write_checkpoint(step))
        state, folder = load_partial(partial)
        assert state["iteration"] == step
        assert checkpoint_contents(folder) == (f"weights {step}", f"replay {step}")
        assert sorted(p.name for p in partial.iterdir()) == [folder.name, "state.json"]


def test_a_save_killed_halfway_leaves_the_previous_save_whole(tmp_path: Path) -> None:
    partial = tmp_path / "run.partial"
    save_partial(partial, {"iteration": 1}, write_checkpoint(1))
    save_partial(partial, {"iteration": 2}, write_checkpoint(2))

    def killed(folder: Path) -> None:  # the weights written, then the process dies
        (folder / "weights").write_text("weights 3")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        save_partial(partial, {"iteration": 3}, killed)
    state, folder = load_partial(partial)
    assert state["iteration"] == 2
    assert checkpoint_contents(folder) == ("weights 2", "replay 2")

    # the next save after the resume overwrites the broken folder, not the good one
    save_partial(partial, {"iteration": 3}, write_checkpoint(3))
    state, folder = load_partial(partial)
    assert (state["iteration"], checkpoint_contents(folder)) == (3, ("weights 3", "replay 3"))


def test_a_save_from_before_the_folders_alternated_is_read_from_the_run_folder(
    tmp_path: Path,
) -> None:
    partial = tmp_path / "run.partial"
    partial.mkdir()
    write_checkpoint(7)(partial)
    (partial / "state.json").write_text(json.dumps({"steps": 7}))
    state, folder = load_partial(partial)
    assert state == {"steps": 7} and checkpoint_contents(folder) == ("weights 7", "replay 7")

    save_partial(partial, {"steps": 8}, write_checkpoint(8))
    state, folder = load_partial(partial)
    assert (state["steps"], checkpoint_contents(folder)) == (8, ("weights 8", "replay 8"))
    assert folder != partial
