"""Tuned examples for the online cross-dynamics families: MuJoCo shift (SAC) and
traffic density (PPO).

Every file is loaded and validated by the CLI's own pre-Ray path (`experiment.load_file` +
`experiment.validate`: keys, asor block, env built with its env_config, RLlib's validate());
one SAC+ASOR and one PPO+ASOR file are trained for real with `rllib train file X --test`
in-process, and their last result must carry the `asor/...` statistics.
"""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import pytest

from rllib_asor.asor.config import AsorConfig
from rllib_asor.cli import experiment
from rllib_asor.cli.main import main

REPO = Path(__file__).resolve().parents[2]
MUJOCO = sorted((REPO / "tuned_examples/mujoco").glob("*.yaml"))
HIGHWAY = sorted((REPO / "tuned_examples/highway").glob("*.yaml"))


def _run(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(argv)
    return rc, out.getvalue(), err.getvalue()


def _last_result(experiment_dir: Path) -> tuple[Path, dict]:
    [trial] = [p for p in experiment_dir.iterdir() if p.is_dir()]
    lines = (trial / "result.json").read_text().strip().splitlines()
    return trial, json.loads(lines[-1])


@pytest.mark.parametrize("path", MUJOCO + HIGHWAY, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_asor_examples_use_the_robust_default_and_srpo_examples_the_paper(path):
    """Validation itself: tests/examples/test_every_example.py."""
    [exp] = experiment.load_file(str(path))
    mode = {"asor": "asor", "srpo": "srpo"}.get(path.stem.split("-")[1] if "-" in path.stem else "")
    if mode is None:
        assert exp.asor is None
    else:
        cfg_asor = AsorConfig.from_dict(exp.asor)
        assert cfg_asor.mode == mode
        assert cfg_asor.preset == ("robust" if mode == "asor" else "paper")


# The trial samples in its own actor: two remote EnvRunners (what `--test` starts) are two more
# processes that import torch and the env; tests/cli/test_e2e.py trains `--test` with them.
LOCAL_SAMPLING = ("--num-env-runners", "0")


def _patched(tmp_path: Path, name: str, replace: dict[str, str]) -> Path:
    """A copy of tuned_examples/NAME with exact text replacements (each must match once)."""
    text = (REPO / "tuned_examples" / name).read_text()
    for old, new in replace.items():
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    path = tmp_path / Path(name).name
    path.write_text(text)
    return path


def _assert_asor_metrics(result: dict) -> None:
    asor = result["asor"]
    assert 0.0 <= asor["disc_acc"] <= 1.0
    assert 0.0 <= asor["real_fraction"] <= 0.3  # ≈ ρ1·ρ2 of the partitioned states
    # The robust default: potential shaping of a bonus clipped to ±3, λ × the reward scale.
    bound = 2.0 * 3.0 * asor["lambda"] + 1e-6
    assert -bound <= asor["aug_reward_min"] <= asor["aug_reward_max"] <= bound


def test_sac_asor_hopper_test_run_reports_asor_metrics(tmp_path, ray_session):
    # --test stops after 2 iterations; the file waits 5000 steps before learning, so this copy
    # starts learning after 100 steps (iterations of 80 steps) to reach ASOR updates quickly.
    path = _patched(
        tmp_path,
        "mujoco/sac-asor-hopper.yaml",
        {
            "num_steps_sampled_before_learning_starts: 5000": (
                "num_steps_sampled_before_learning_starts: 100"
            ),
            "min_sample_timesteps_per_iteration: 1000": "min_sample_timesteps_per_iteration: 80",
        },
    )
    rc, out, err = _run(
        ["train", "file", str(path), "--test", "--storage-path", str(tmp_path / "res"),
         *LOCAL_SAMPLING]
    )
    assert rc == 0, err[-3000:]
    trial, result = _last_result(tmp_path / "res/hopper-sac-asor-test")
    assert trial.name.startswith("AsorSAC_")
    assert result["training_iteration"] == 2
    _assert_asor_metrics(result)
    assert json.loads((trial / "params.json").read_text())["asor"] == {"mode": "asor", "seed": 0}


@pytest.mark.slow  # ~50 s of highway-env alone; the env: tests/envs/test_traffic.py, a PPO+ASOR
# `--test` run: tests/cli/test_e2e.py
def test_highway_ppo_asor_test_run_reports_asor_metrics(tmp_path, ray_session):
    # Fewer cars (2-6 instead of 5-20) keep highway-env's O(N²) step cheap; wiring unchanged.
    path = _patched(
        tmp_path,
        "highway/ppo-asor.yaml",
        {"base_vehicles_count: 10": "base_vehicles_count: 3"},
    )
    rc, out, err = _run(
        ["train", "file", str(path), "--test", "--storage-path", str(tmp_path / "res"),
         *LOCAL_SAMPLING]
    )
    assert rc == 0, err[-3000:]
    trial, result = _last_result(tmp_path / "res/highway-ppo-asor-test")
    assert trial.name.startswith("AsorPPO_")
    assert result["training_iteration"] == 2
    assert result["num_env_steps_sampled_lifetime"] >= 512
    _assert_asor_metrics(result)
