"""Real tiny runs (Ray, Tune, RLlib; no mocks): train --test, evaluate, --resume, ASOR, failure.

All tests share one Ray session (`cli_ray`) and call the CLI in-process with `main([...])`.
"""

from __future__ import annotations

import contextlib
import io
import json
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from rllib_asor.cli.main import main

REPO = Path(__file__).resolve().parents[2]

LEGACY_CARTPOLE = """
cartpole-legacy:
  env: CartPole-v1
  run: PPO
  stop: {episode_reward_mean: 150, timesteps_total: 100000}
  config:
    lr: 0.0003
    num_workers: 2
    num_sgd_iter: 6
    sgd_minibatch_size: 128
    model: {fcnet_hiddens: [32, 32]}
  checkpoint_freq: 1
"""


# For runs whose point is not the remote EnvRunners (the `cartpole` run has --test's two): the
# trial samples in its own actor, two processes fewer to start.
LOCAL_SAMPLING = ("--num-env-runners", "0")


def run_cli(argv: list[str]) -> SimpleNamespace:
    """main(argv) with stdout/stderr captured (works in module-scoped fixtures)."""
    out, err = io.StringIO(), io.StringIO()
    t0 = time.monotonic()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(argv)
    return SimpleNamespace(
        rc=rc, out=out.getvalue(), err=err.getvalue(), seconds=time.monotonic() - t0
    )


def trial_dirs(experiment_dir: Path) -> list[Path]:
    return sorted(p for p in experiment_dir.iterdir() if p.is_dir())


def last_result(trial_dir: Path) -> dict:
    lines = (trial_dir / "result.json").read_text().strip().splitlines()
    return json.loads(lines[-1])


@pytest.fixture(scope="module")
def cartpole(tmp_path_factory, cli_ray) -> SimpleNamespace:
    """One `rllib train file legacy.yaml --test` run on CartPole-v1."""
    root = tmp_path_factory.mktemp("cartpole")
    path = root / "legacy.yaml"
    path.write_text(LEGACY_CARTPOLE)
    storage = root / "results"
    res = run_cli(["train", "file", str(path), "--test", "--storage-path", str(storage)])
    res.yaml, res.storage, res.exp_dir = str(path), storage, storage / "cartpole-legacy-test"
    return res


def test_train_test_mode_exits_0_and_writes_checkpoint(cartpole):
    assert cartpole.rc == 0, cartpole.err[-2000:]
    [trial] = trial_dirs(cartpole.exp_dir)
    checkpoints = sorted(trial.glob("checkpoint_*"))
    assert checkpoints and (checkpoints[-1] / "rllib_checkpoint.json").is_file()
    result = last_result(trial)
    assert result["training_iteration"] == 2  # --test budget
    assert result["num_env_steps_sampled_lifetime"] > 0
    assert result["config"]["num_env_runners"] == 2
    assert result["config"]["num_cpus_per_env_runner"] == 0.5
    assert result["config"]["_model_config"] == {"fcnet_hiddens": [32, 32]}


def test_train_prints_legacy_warnings_progress_lines_and_summary(cartpole):
    assert "rllib: warning:" in cartpole.err
    assert "'num_sgd_iter' translated to 'num_epochs'" in cartpole.err
    progress = [line for line in cartpole.out.splitlines() if line.startswith("[0] it ")]
    assert progress and all(len(line) <= 100 for line in progress)
    assert " steps " in progress[-1] and " return " in progress[-1]
    assert "rllib: cartpole-legacy-test: 1 trial(s), 0 errored" in cartpole.out
    assert "checkpoint=" + str(cartpole.exp_dir) in cartpole.out


def test_evaluate_checkpoint_json(cartpole):
    [trial] = trial_dirs(cartpole.exp_dir)
    checkpoint = sorted(trial.glob("checkpoint_*"))[-1]
    res = run_cli(["evaluate", str(checkpoint), "--episodes", "3", "--json"])
    assert res.rc == 0, res.err[-2000:]
    stats = json.loads(res.out.strip().splitlines()[-1])
    assert stats["episodes"] == 3 and len(stats["returns"]) == 3
    assert stats["env"] == "CartPole-v1"
    assert stats["return_mean"] == pytest.approx(sum(stats["returns"]) / 3)
    assert stats["seed"] == 1_000_000  # rllib ab's evaluation seed, by default


def test_evaluate_finds_latest_checkpoint_in_experiment_dir(cartpole):
    res = run_cli(["evaluate", str(cartpole.exp_dir), "--episodes", "2"])
    assert res.rc == 0, res.err[-2000:]
    assert "return: mean" in res.out and "episode returns:" in res.out
    assert "checkpoint_" in res.out
    assert "seed: 1000000 (the default: the seed rllib ab evaluates with)" in res.out


def test_evaluate_all_checkpoints_names_each_trials_best_beside_its_newest(cartpole):
    [trial] = trial_dirs(cartpole.exp_dir)
    written = sorted(str(p) for p in trial.glob("checkpoint_*"))
    assert len(written) >= 2  # checkpoint_freq: 1, two iterations
    res = run_cli(
        ["evaluate", str(cartpole.exp_dir), "--all-checkpoints", "--episodes", "2", "--json"]
    )
    assert res.rc == 0, res.err[-2000:]
    out = json.loads(res.out.strip().splitlines()[-1])
    assert [c["checkpoint"] for c in out["checkpoints"]] == written
    [best] = out["best"]
    assert best["best_value"] == max(c["return_mean"] for c in out["checkpoints"])
    assert best["newest"] == written[-1] and best["by"] == "return_mean"
    res = run_cli(["evaluate", str(cartpole.exp_dir), "--all-checkpoints", "--episodes", "1"])
    assert res.rc == 0, res.err[-2000:]
    assert f"{len(written)} checkpoints under {cartpole.exp_dir}: evaluating every one" in res.out
    assert res.out.count("checkpoint: ") == len(written)
    [line] = [x for x in res.out.splitlines() if x.startswith("best by return_mean in ")]
    assert f"; the newest, {Path(written[-1]).name}: " in line
    res = run_cli(["evaluate", str(cartpole.exp_dir), "--all-checkpoints", "--episodes", "1",
                   "--best-by", "success"])  # fmt: skip
    assert res.rc == 2
    assert res.err.strip().splitlines() == [
        "rllib evaluate: error: --best-by: 'success' is not a number this evaluation reports; "
        "allowed: return_mean, return_min, return_max"
    ], res.err


def test_test_run_rerun_starts_its_smoke_folder_over_and_refuses_resume(cartpole):
    """A --test run is a smoke run in NAME-test: it is not resumed (real runs are:
    tests/cli/test_experiment_folder.py)."""
    argv = ["train", "file", cartpole.yaml, "--test", "--storage-path", str(cartpole.storage)]
    res = run_cli([*argv, "--resume"])
    assert res.rc == 2 and "smoke runs start over" in res.err
    assert [p.name for p in cartpole.storage.iterdir()] == ["cartpole-legacy-test"]


def test_asor_lava_example_test_run_reports_asor_metrics(tmp_path, cli_ray):
    res = run_cli(
        [
            "train",
            "file",
            str(REPO / "tuned_examples/lava/ppo-asor.yaml"),
            "--test",
            "--storage-path",
            str(tmp_path),
            *LOCAL_SAMPLING,
        ]
    )
    assert res.rc == 0, res.err[-3000:]
    [trial] = trial_dirs(tmp_path / "lava-ppo-asor-test")
    assert trial.name.startswith("AsorPPO_")
    params = json.loads((trial / "params.json").read_text())  # the trial's resolved param space
    assert params["asor"] == {"mode": "asor"}  # the robust default
    result = last_result(trial)
    assert 0.0 <= result["asor"]["disc_acc"] <= 1.0
    assert any(  # the progress line shows the discriminator's accuracy
        line.startswith("[0] it ") and " disc " in line for line in res.out.splitlines()
    )


def test_failing_trial_exits_1(tmp_path, write_yaml, cli_ray):
    import gymnasium as gym
    from ray import tune

    class FailsWhenStepped(gym.Env):  # builds fine (validation passes), fails in training
        observation_space = gym.spaces.Box(-1.0, 1.0, (2,))
        action_space = gym.spaces.Discrete(2)

        def reset(self, *, seed=None, options=None):
            return self.observation_space.sample(), {}

        def step(self, action):
            raise RuntimeError("this env always fails when stepped")

    tune.register_env("cli-test/FailsInTraining-v0", lambda cfg: FailsWhenStepped())
    assert "cli-test/FailsInTraining-v0" not in gym.registry
    path = write_yaml("""
        fails:
          env: cli-test/FailsInTraining-v0
          run: PPO
          config: {restart_failed_env_runners: false}
    """)
    res = run_cli(
        ["train", "file", path, "--test", "--storage-path", str(tmp_path), *LOCAL_SAMPLING]
    )
    assert res.rc == 1
    assert "1 errored" in res.out


def test_env_that_cannot_be_built_exits_2_in_one_line_before_ray(tmp_path, write_yaml, cli_ray):
    from ray import tune

    def failing_env(env_config):
        raise RuntimeError("this env always fails to build")

    tune.register_env("cli-test/AlwaysFails-v0", failing_env)
    path = write_yaml("""
        fails:
          env: cli-test/AlwaysFails-v0
          run: PPO
    """)
    res = run_cli(["train", "file", path, "--test", "--storage-path", str(tmp_path)])
    assert res.rc == 2
    lines = [line for line in res.err.splitlines() if line.strip()]
    assert len(lines) == 1 and "this env always fails to build" in lines[0], res.err


def test_evaluate_damaged_checkpoint_exits_2_naming_the_file(cartpole, tmp_path):
    import shutil

    [trial] = trial_dirs(cartpole.exp_dir)
    copy = tmp_path / "checkpoint_copy"
    shutil.copytree(sorted(trial.glob("checkpoint_*"))[-1], copy)
    target = copy / "learner_group/learner/rl_module/default_policy/module_state.pkl"
    target.write_bytes(target.read_bytes()[: target.stat().st_size // 2])
    res = run_cli(["evaluate", str(copy), "--episodes", "1"])
    assert res.rc == 2
    lines = res.err.strip().splitlines()
    assert len(lines) == 1 and str(target) in lines[0] and "damaged" in lines[0], res.err
