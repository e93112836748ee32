"""Env knowledge comes from the family registry (rllib_asor.registry.families), not the CLI."""

from __future__ import annotations

from pathlib import Path

import pytest

from rllib_asor.cli import experiment
from rllib_asor.cli.errors import UsageError
from rllib_asor.registry.families import RACE, family_of


def test_family_lookup_by_env_id():
    assert family_of("game_env/ObstacleRace-v0") is RACE
    assert family_of("game_env/ObstacleRaceMulti-v0") is RACE
    assert family_of("CartPole-v1") is None and family_of("rllib_asor/LavaWorld-v0") is None


def test_race_from_flags_gets_the_family_defaults():
    """`rllib train --run PPO --env game_env/ObstacleRace-v0 --test`: the race network, the race
    metrics and a short episode limit, with nothing in the config."""
    from rllib_asor.race.config import RaceMetricsCallback
    from rllib_asor.race.net import RaceNetModule

    exp = experiment.from_flags("PPO", "game_env/ObstacleRace-v0", None, None)
    experiment.apply_overrides(exp, test=True)
    assert (
        exp.config["env_config"]["max_episode_steps"] == RACE.test_env_config["max_episode_steps"]
    )
    config = experiment.validate(exp)
    assert config.rl_module_spec.module_class is RaceNetModule
    classes = config.callbacks_class
    assert RaceMetricsCallback in (classes if isinstance(classes, list) else [classes])


def test_curriculum_outside_a_family_that_has_one_names_the_allowed_envs(tmp_path: Path):
    path = tmp_path / "x.yaml"
    path.write_text(
        "x:\n  env: CartPole-v1\n  run: PPO\n  config: {curriculum: {stages: [[0], random]}}\n"
    )
    with pytest.raises(UsageError, match=r"curriculum.*allowed envs: game_env/\.\.\..*CartPole-v1"):
        experiment.validate(experiment.load_file(str(path))[0])


def _validated_race_file(tmp_path: Path, config: str):
    """The validated config of a one-experiment race PPO file whose `config:` is `config`."""
    path = tmp_path / "x.yaml"
    path.write_text(
        "x:\n  env: game_env/ObstacleRace-v0\n  run: PPO\n  stop: {training_iteration: 2}\n"
        f"  config: {config}\n"
    )
    return experiment.validate(experiment.load_file(str(path))[0])


@pytest.mark.parametrize("given, expected", [("", False), ("normalize_actions: true, ", True)])
def test_race_actions_are_not_unsquashed_unless_the_file_asks(tmp_path: Path, given, expected):
    """The race's actions are discrete: RLlib's unsquash/clip are no-ops there (and cost time)."""
    from rllib_asor.race.config import race_ppo_config

    config = _validated_race_file(tmp_path, f"{{{given}lr: 0.001}}")
    assert config.normalize_actions is expected and config.clip_actions is False
    assert race_ppo_config().normalize_actions is False


@pytest.mark.parametrize("given, expected", [("", "lean"), ("step_info: full, ", "full")])
def test_race_envs_leave_out_per_step_terms_unless_the_file_asks(tmp_path: Path, given, expected):
    """No Learner or callback reads the race's per-step reward terms and running metrics."""
    from rllib_asor.race.config import race_ppo_config

    config = _validated_race_file(tmp_path, f"{{env_config: {{{given}map_id: 2}}}}")
    assert config.env_config == {"step_info": expected, "map_id": 2}
    assert race_ppo_config().env_config["step_info"] == "lean"
    full = race_ppo_config(env_config={"step_info": "full"})
    assert full.env_config["step_info"] == "full"


def test_drop_bootstrap_rows_in_a_ppo_file_gets_the_lean_learner(tmp_path: Path):
    from rllib_asor.algorithms.ppo.lean import LeanPPOTorchLearner

    path = tmp_path / "x.yaml"
    path.write_text(
        "x:\n  env: CartPole-v1\n  run: PPO\n"
        "  config: {learner_config_dict: {drop_bootstrap_rows: true}}\n"
    )
    config = experiment.build_algo_config(experiment.load_file(str(path))[0])
    assert config.learner_class is LeanPPOTorchLearner
