"""`rllib ab` end to end, as a new user would run it: their own CartPole whose pole length
changes per episode (a module of their own, reporting ``info["dynamics_id"]``), 2 paired seeds,
a tiny budget; then `rllib compare` on the same folder, and a rerun that resumes."""

from __future__ import annotations

import importlib.util
import json
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from rllib_asor.cli.main import main

VARPOLE = '''
import gymnasium as gym
from gymnasium.envs.classic_control.cartpole import CartPoleEnv


class VarPoleCartPole(CartPoleEnv):
    """CartPole whose pole half-length is drawn per episode from `lengths`;
    info["dynamics_id"] = the length in cm."""

    def __init__(self, config=None):
        super().__init__()
        self.lengths = list((config or {}).get("lengths", [0.25, 0.5, 0.75]))
        self.dynamics = None

    def reset(self, *, seed=None, options=None):
        obs, info = super().reset(seed=seed, options=options)
        self.length = self.lengths[int(self.np_random.integers(len(self.lengths)))]
        self.polemass_length = self.masspole * self.length
        self.dynamics = int(round(self.length * 100))
        return obs, {**info, "dynamics_id": self.dynamics}

    def step(self, action):
        obs, reward, terminated, truncated, info = super().step(action)
        return obs, reward, terminated, truncated, {**info, "dynamics_id": self.dynamics}


def make(config):
    return gym.wrappers.TimeLimit(VarPoleCartPole(config), 200)
'''

YAML = """
varpole:
  env: MyVarPole-v0
  run: PPO
  stop: {training_iteration: 1}
  config:
    num_env_runners: 0
    train_batch_size: 256
    minibatch_size: 64
    num_epochs: 1
    model_config: {fcnet_hiddens: [16]}
    evaluation_duration: 3
    evaluation_config: {env_config: {lengths: [0.5, 1.0]}}   # 1.0: never seen in training
    asor: {mode: asor}
"""


@pytest.fixture
def my_env(tmp_path: Path, cli_ray: None) -> str:
    """The user's module, in a temporary folder, its env registered with Tune (pickled by
    value, so Ray's worker processes need not import the folder)."""
    import ray.cloudpickle
    from ray import tune

    (tmp_path / "myvarpole.py").write_text(VARPOLE)
    spec = importlib.util.spec_from_file_location("myvarpole", tmp_path / "myvarpole.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["myvarpole"] = mod
    spec.loader.exec_module(mod)
    ray.cloudpickle.register_pickle_by_value(mod)
    tune.register_env("MyVarPole-v0", mod.make)
    return "MyVarPole-v0"


def _ab_two_seeds(write_yaml: Callable[..., str], store: Path) -> tuple[list[str], Path]:
    """`rllib ab` of YAML with 2 paired seeds into `store`: (its argv, the experiment folder)."""
    argv = ["ab", write_yaml(YAML, "varpole.yaml"), "--seeds", "2", "--episodes", "6",
            "--storage-path", str(store)]  # fmt: skip
    assert main(argv) == 0
    return argv, store / "varpole-ab"


def test_ab_on_a_users_env_with_changing_dynamics(
    my_env: str,
    tmp_path: Path,
    write_yaml: Callable[..., str],
    capsys: pytest.CaptureFixture[str],
) -> None:
    argv, exp = _ab_two_seeds(write_yaml, tmp_path / "results")
    out = capsys.readouterr().out
    trials = sorted(p.parent for p in exp.rglob("result.json"))
    assert len(trials) == 4
    # Greedy evaluation during training, per dynamics id, through RLlib's evaluation runners.
    rows = [json.loads(line) for line in (trials[0] / "result.json").read_text().splitlines()]
    dyn = rows[-1]["evaluation"]["env_runners"]["dynamics"]
    assert set(dyn) <= {"50", "100"} and dyn
    # Every final checkpoint evaluated on the same episodes (same env seed).
    evals = [json.loads((t / "evaluation.json").read_text()) for t in trials]
    assert {e["seed"] for e in evals} == {1_000_000} and all(e["episodes"] == 6 for e in evals)
    assert all(set(e["dynamics_ids"]) <= {50, 100} for e in evals)
    # The paired result, its interval, a p-value and the per-dynamics table.
    assert "| PPO+ASOR | PPO | 2 |" in out and "Wilcoxon signed-rank" in out
    assert "score: final evaluation return" in out and "per dynamics_id:" in out
    for name in ("compare.md", "compare.json", "curves_training.png", "paired.png"):
        assert (exp / "ab" / name).is_file(), name
    params = [json.loads((t / "params.json").read_text()) for t in trials]
    assert sorted((p["rllib_asor_arm"], p["seed"], p["asor"] is None) for p in params) == [
        ("PPO", 0, True), ("PPO", 1, True), ("PPO+ASOR", 0, False), ("PPO+ASOR", 1, False),
    ]  # fmt: skip

    # `rllib compare` on the same folder: the same numbers, and the JSON keys.
    assert main(["compare", str(exp), "--json"]) == 0
    (overall, *per_dyn) = json.loads(capsys.readouterr().out)
    ab_json = json.loads((exp / "ab" / "compare.json").read_text())
    assert overall["diff_mean"] == ab_json[0]["diff_mean"] and overall["pairs"] == 2
    assert {r["dynamics"] for r in per_dyn} <= {"50", "100"}

    # `rllib evaluate` on the experiment folder evaluates every trial, per dynamics id.
    assert main(["evaluate", str(exp), "--episodes", "2", "--evaluation-config"]) == 0
    text = capsys.readouterr().out
    assert text.startswith(f"4 trials under {exp}: evaluating the newest checkpoint of each")
    assert text.count("checkpoint: ") == 4 and text.count("return per dynamics_id: ") == 4
    # The same name with a changed setting is refused, naming the change and the ways out.
    write_yaml(YAML.replace("num_epochs: 1", "num_epochs: 2"), "varpole.yaml")
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "num_epochs: 1 -> 2" in err and "--name" in err and "--fresh" in err
    assert len(list(exp.rglob("result.json"))) == 4


# ~70 s, `make test-slow`: a rerun of the same `rllib train` experiment resumes
# (tests/cli/test_experiment_folder.py, the same manifest code); a changed `ab` is refused above.
@pytest.mark.slow
def test_ab_rerun_resumes_and_more_seeds_add_pairs(
    my_env: str,
    tmp_path: Path,
    write_yaml: Callable[..., str],
    capsys: pytest.CaptureFixture[str],
) -> None:
    argv, exp = _ab_two_seeds(write_yaml, tmp_path / "results")
    capsys.readouterr()
    trials = sorted(p.parent for p in exp.rglob("result.json"))

    # A rerun resumes: nothing trains again, the evaluations are kept.
    before = [(t / "evaluation.json").stat().st_mtime_ns for t in trials]
    assert main(argv) == 0
    assert "resuming" in capsys.readouterr().out
    assert [(t / "evaluation.json").stat().st_mtime_ns for t in trials] == before
    # More seeds: only the new seed trains (its own Tune experiment in the folder); the old
    # trials and their evaluations are kept, the comparison has three pairs.
    assert main([*argv[:3], "3", *argv[4:]]) == 0
    out = capsys.readouterr().out
    assert "| PPO+ASOR | PPO | 3 |" in out
    now = sorted(p.parent for p in exp.rglob("result.json"))
    assert len(now) == 6 and set(trials) <= set(now)
    assert [(t / "evaluation.json").stat().st_mtime_ns for t in trials] == before


def test_ab_bad_input_is_one_line(
    write_yaml: Callable[..., str], capsys: pytest.CaptureFixture[str]
) -> None:
    plain = write_yaml(YAML.replace("    asor: {mode: asor}\n", ""), "plain.yaml")
    assert main(["ab", plain, "--seeds", "2"]) == 2
    err = capsys.readouterr().err
    assert "has no asor: block" in err and err.count("\n") == 1
    assert main(["ab", plain, "--seeds", "1"]) == 2
    assert "--seeds: 1 is invalid" in capsys.readouterr().err
    swept = write_yaml(YAML.replace("num_epochs: 1", "num_epochs: {grid_search: [1, 2]}"), "g.yaml")
    assert main(["ab", swept, "--seeds", "2"]) == 2
    assert "grid_search" in capsys.readouterr().err
    other = write_yaml(YAML.replace("MyVarPole-v0", "CartPole-v1"), "other.yaml")
    assert main(["ab", plain, "--seeds", "2", "--vs", other]) == 2
    assert "allowed: the same run and env (paired seeds)" in capsys.readouterr().err


def test_ab_with_gpus_on_a_machine_without_one_is_one_line(
    write_yaml: Callable[..., str],
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
) -> None:
    monkeypatch.setattr("rllib_asor.cli.overrides.cuda_available", lambda: False)
    gpu = write_yaml(
        "x:\n  env: CartPole-v1\n  run: PPO\n  stop: {training_iteration: 1}\n"
        "  config: {num_gpus_per_learner: 1, asor: {mode: asor}}\n"
    )
    argv = ["ab", gpu, "--seeds", "2", "--storage-path", str(tmp_path / "out")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "num_gpus_per_learner: 1" in err and "torch sees no CUDA device" in err
    assert err.count("\n") == 1 and not (tmp_path / "out").exists()
