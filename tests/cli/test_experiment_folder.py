"""An experiment folder holds what was asked (`rllib_asor.cli.manifest`): a rerun of the same
experiment resumes, a changed one is refused in one line naming the difference and the ways out
(`--name`, `--fresh`), and `--test` smoke runs never share a folder with real runs."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from rllib_asor.cli import manifest
from rllib_asor.cli.errors import UsageError
from tests.cli.test_e2e import run_cli

TINY = """
tiny:
  env: CartPole-v1
  run: PPO
  stop: {{training_iteration: 1}}
  config:
    lr: {lr}
    num_env_runners: 0
    train_batch_size: 128
    minibatch_size: 64
    num_epochs: 1
    model_config: {{fcnet_hiddens: [8]}}
"""


def _trials(folder: Path) -> list[Path]:
    return sorted(p.parent for p in folder.rglob("result.json"))


def test_differences_name_each_changed_key_with_both_values() -> None:
    held = {"config": {"lr": 3e-4, "gamma": 0.99}, "stop": {"num_env_steps_sampled_lifetime": 20000}}
    wanted = {"config": {"lr": 1e-3, "gamma": 0.99, "vf_clip_param": 10}, "stop": {
        "num_env_steps_sampled_lifetime": 30000}}  # fmt: skip
    assert manifest.differences(held, wanted) == [
        "config.lr: 0.0003 -> 0.001",
        "config.vf_clip_param: (unset) -> 10",
        "stop.num_env_steps_sampled_lifetime: 20000 -> 30000",
    ]
    assert manifest.differences(held, held) == []


def test_a_changed_folder_is_refused_and_fresh_moves_the_old_one_aside(tmp_path: Path) -> None:
    folder = str(tmp_path / "exp")
    first = {"config": {"lr": 0.0003}, "smoke": False}
    assert manifest.prepare(folder, first, fresh=False, smoke=False) == (first, False)
    (tmp_path / "exp" / "trial_0").mkdir()
    assert manifest.prepare(folder, first, fresh=False, smoke=False)[1] is True
    with pytest.raises(UsageError) as e:
        manifest.prepare(folder, {**first, "config": {"lr": 0.001}}, fresh=False, smoke=False)
    text = str(e.value)
    assert "config.lr: 0.0003 -> 0.001" in text and "--name" in text and "--fresh" in text
    assert "\n" not in text
    # --fresh: the old folder renamed, nothing deleted, the new record in place.
    manifest.prepare(folder, {**first, "config": {"lr": 0.001}}, fresh=True, smoke=False)
    [old] = list(tmp_path.glob("exp.replaced-*"))
    assert (old / "trial_0").is_dir()
    assert manifest.read(folder)["config"] == {"lr": 0.001}


def test_results_without_a_record_and_smoke_runs_over_real_ones_are_refused(tmp_path) -> None:
    (tmp_path / "old" / "trial_0").mkdir(parents=True)
    with pytest.raises(UsageError, match="without a record of what was run.*--fresh"):
        manifest.prepare(str(tmp_path / "old"), {"smoke": False}, fresh=False, smoke=False)
    with pytest.raises(UsageError, match="not --test smoke runs"):
        manifest.prepare(str(tmp_path / "old"), {"smoke": True}, fresh=False, smoke=True)
    assert (tmp_path / "old" / "trial_0").is_dir()


def test_train_rerun_resumes_the_same_and_refuses_a_changed_experiment(
    tmp_path: Path, cli_ray: None
) -> None:
    path = tmp_path / "tiny.yaml"
    path.write_text(TINY.format(lr=0.0003))
    store = str(tmp_path / "results")
    argv = ["train", "file", str(path), "--storage-path", store]
    first = run_cli(argv)
    assert first.rc == 0, first.err[-2000:]
    folder = tmp_path / "results" / "tiny"
    [trial] = _trials(folder)

    again = run_cli(argv)
    assert again.rc == 0, again.err[-2000:]
    assert "resuming" in again.out and _trials(folder) == [trial]

    path.write_text(TINY.format(lr=0.001))
    changed = run_cli(argv)
    assert changed.rc == 2 and changed.out == ""
    [line] = changed.err.strip().splitlines()
    assert "config.lr: 0.0003 -> 0.001" in line and "--name" in line and "--fresh" in line
    assert json.loads((trial / "params.json").read_text())["lr"] == 0.0003

    stop = run_cli([*argv[:-2], "--storage-path", store, "--stop", "training_iteration=2"])
    assert stop.rc == 2 and "stop.training_iteration: 1 -> 2" in stop.err
    path.write_text(TINY.format(lr=0.0003))
    fresh = run_cli([*argv, "--stop", "training_iteration=2", "--fresh"])
    assert fresh.rc == 0, fresh.err[-2000:]
    [new] = _trials(folder)
    assert json.loads((new / "result.json").read_text().splitlines()[-1])[
        "training_iteration"] == 2  # fmt: skip
    [moved] = list((tmp_path / "results").glob("tiny.replaced-*"))
    assert _trials(moved)[0].name == trial.name


def test_test_runs_go_to_their_own_folder_marked_smoke(tmp_path: Path, cli_ray: None) -> None:
    path = tmp_path / "tiny.yaml"
    path.write_text(TINY.format(lr=0.0003))
    store = tmp_path / "results"
    # No remote runners (two more processes to start): the folder is what this test checks.
    res = run_cli(["train", "file", str(path), "--test", "--num-env-runners", "0",
                   "--storage-path", str(store)])  # fmt: skip
    assert res.rc == 0, res.err[-2000:]
    assert not (store / "tiny").exists()
    [trial] = _trials(store / "tiny-test")
    assert json.loads((trial / "params.json").read_text())["rllib_asor_smoke"] is True
    resumed = run_cli(["train", "file", str(path), "--test", "--resume", "--storage-path",
                       str(store)])  # fmt: skip
    assert resumed.rc == 2 and "smoke runs" in resumed.err


def test_ab_differences_are_named_once_for_both_arms_and_per_arm_otherwise(tmp_path) -> None:
    arm = {"config": {"lr": 0.0003}, "asor": None}
    held = {"command": "ab", "arms": {"PPO": arm, "PPO+ASOR": {**arm, "asor": {"lambda_": 0.1}}}}
    manifest.write(str(tmp_path), held)
    wanted = {"command": "ab", "arms": {
        "PPO": {**arm, "config": {"lr": 0.001}},
        "PPO+ASOR": {"config": {"lr": 0.001}, "asor": {"lambda_": 0.3}}}}  # fmt: skip
    with pytest.raises(UsageError) as e:
        manifest.prepare(str(tmp_path), wanted, fresh=False, smoke=False)
    text = str(e.value)
    assert "config.lr: 0.0003 -> 0.001;" in text and "arms." not in text
    assert "PPO+ASOR: asor.lambda_: 0.1 -> 0.3" in text


def test_a_config_holding_functions_or_objects_matches_its_own_record_again() -> None:
    def connector(env, spaces, device):  # a config value whose repr names a memory address
        return None

    class Thing:
        pass

    exp = type("Exp", (), {"run": "PPO", "env": "CartPole-v1", "stop": {}, "asor": None,
                           "num_samples": 1, "checkpoint_config": {},
                           "config": {"env_to_module_connector": connector, "x": Thing()}})()  # fmt: skip
    first = manifest.describe(exp, smoke=False)
    exp.config = {"env_to_module_connector": connector, "x": Thing()}
    assert manifest.describe(exp, smoke=False) == first
    assert "0x" not in json.dumps(first)


def test_a_folder_another_command_runs_in_is_neither_resumed_nor_removed(tmp_path) -> None:
    import subprocess
    import sys

    folder = tmp_path / "tiny-test"
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from rllib_asor.cli import manifest; "
         f"manifest.prepare({str(folder)!r}, {{'smoke': True}}, fresh=False, smoke=True); "
         "print('held', flush=True); time.sleep(60)"],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "held"
        for kw in ({"fresh": False, "smoke": True}, {"fresh": True, "smoke": False}):
            with pytest.raises(UsageError, match="another rllib command is running"):
                manifest.prepare(str(folder), {"smoke": kw["smoke"]}, **kw)
        assert manifest.read(str(folder)) == {"smoke": True}
    finally:
        holder.kill()
        holder.wait()
    # the holder gone, its lock goes with it: a new smoke run starts the folder over
    assert manifest.prepare(str(folder), {"smoke": True}, fresh=False, smoke=True)[1] is False
