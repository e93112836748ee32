"""Env knowledge comes from the family registry (rllib_asor.rllib.env_families), not the CLI."""

from __future__ import annotations

from pathlib import Path

import pytest

from rllib_asor.cli import experiment
from rllib_asor.cli.errors import UsageError
from rllib_asor.rllib.env_families import RACE, family_of


def test_family_lookup_by_env_id():
    assert family_of("game_env/ObstacleRace-v0") is RACE
    assert family_of("game_env/ObstacleRaceMulti-v0") is RACE
    assert family_of("CartPole-v1") is None and family_of("rllib_asor/LavaWorld-v0") is None


def test_race_from_flags_gets_the_family_defaults():
    """`rllib train --run PPO --env game_env/ObstacleRace-v0 --test`: the race network, the race
    metrics and a short episode limit, with nothing in the config."""
    from rllib_asor.models.race_net import RaceNetModule
    from rllib_asor.rllib.race import RaceMetricsCallback

    exp = experiment.from_flags("PPO", "game_env/ObstacleRace-v0", None, None)
    experiment.apply_overrides(exp, test=True)
    assert (
        exp.config["env_config"]["max_episode_steps"] == RACE.test_env_config["max_episode_steps"]
    )
    config = experiment.validate(exp)
    assert config.rl_module_spec.module_class is RaceNetModule
    assert config.callbacks_class is RaceMetricsCallback


def test_curriculum_outside_a_family_that_has_one_names_the_allowed_envs(tmp_path: Path):
    path = tmp_path / "x.yaml"
    path.write_text(
        "x:\n  env: CartPole-v1\n  run: PPO\n  config: {curriculum: {stages: [[0], random]}}\n"
    )
    with pytest.raises(UsageError, match=r"curriculum.*allowed envs: game_env/\.\.\..*CartPole-v1"):
        experiment.validate(experiment.load_file(str(path))[0])
