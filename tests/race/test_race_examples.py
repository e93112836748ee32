"""tuned_examples/race/*.yaml and sweeps/race-*.yaml: all validate; ppo-asor.yaml runs with --test.

The `--test` run is the README's `make train` (in-process `main([...])`, Ray reused); it is
marked `slow` (a few minutes on 2 busy cores). The other files are only validated
(`experiment.validate`: the env is built, RLlib's `AlgorithmConfig.validate()` runs).
"""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import pytest

from rllib_asor.cli import experiment
from rllib_asor.cli.main import main

REPO = Path(__file__).resolve().parents[2]
RACE_YAMLS = sorted((REPO / "tuned_examples/race").glob("*.yaml")) + sorted(
    (REPO / "tuned_examples/sweeps").glob("race-*.yaml")
)


@pytest.mark.parametrize("path", RACE_YAMLS, ids=lambda p: p.name)
def test_race_example_gets_the_race_network_metrics_and_asor_inputs(path):
    for exp in experiment.load_file(str(path)):
        cfg = experiment.validate(exp)
        assert exp.warnings == []  # no legacy keys in our own examples
        assert exp.env.startswith("game_env/ObstacleRace")
        assert cfg._rl_module_spec.module_class.__name__ == "RaceNetModule"
        callbacks = cfg.callbacks_class
        callbacks = callbacks if isinstance(callbacks, list) else [callbacks]
        assert callbacks[0].__name__ == "RaceMetricsCallback"
        if exp.asor is not None:
            assert exp.asor["obs_keys"] == ["agent", "destination"]
        if exp.env.endswith("Multi-v0"):
            assert cfg.is_multi_agent and set(cfg.policies) == {"shared"}
            assert cfg.policy_mapping_fn("racer_3", None) == "shared"


def test_curriculum_example_adds_the_map_curriculum():
    from rllib_asor.race.curriculum import MapCurriculumCallback

    [exp] = experiment.load_file(str(REPO / "tuned_examples/race/ppo-asor-curriculum.yaml"))
    cfg = experiment.validate(exp)
    _, curriculum = cfg.callbacks_class
    assert issubclass(curriculum, MapCurriculumCallback)
    assert curriculum.curriculum.stages == ((6, 2), (6, 2, 8, 7, 1), None)
    assert "curriculum" not in experiment.param_space(exp, cfg)  # applied as a callback, not a key


def test_race_sweep_expands_lambda_rho_and_seeds():
    [exp] = experiment.load_file(str(REPO / "tuned_examples/sweeps/race-asor.yaml"))
    assert exp.num_trials == 24
    space = experiment.param_space(exp, experiment.validate(exp))
    assert set(space["asor"]) >= {"lambda_", "rho_value", "rho_count"}
    assert "grid_search" in space["seed"]


@pytest.mark.slow
def test_ppo_asor_example_test_run_reports_asor_and_race_metrics(tmp_path, ray_session):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(
            [
                "train",
                "file",
                str(REPO / "tuned_examples/race/ppo-asor.yaml"),
                "--test",
                "--storage-path",
                str(tmp_path),
            ]
        )
    assert rc == 0, err.getvalue()[-3000:]
    [trial] = [p for p in (tmp_path / "race-ppo-asor-test").iterdir() if p.is_dir()]
    assert trial.name.startswith("AsorPPO_game_env_ObstacleRace-v0")
    lines = (trial / "result.json").read_text().strip().splitlines()
    result = json.loads(lines[-1])
    assert result["training_iteration"] == 2
    assert 0.0 <= result["asor"]["disc_acc"] <= 1.0
    assert "rnd_loss" in result["asor"]
    race = result["race"]
    assert 0.0 <= race["success_rate"] <= 1.0 and 0.0 <= race["trapped_rate"] <= 1.0
    assert race["policy_entropy"] > 0.0
