"""The YAML `multi_agent:` block (shared policy) and the race envs/callbacks through the CLI.

Validation only (no Ray, no training): `experiment.validate` builds the env once and runs RLlib's
`AlgorithmConfig.validate()`.
"""

from __future__ import annotations

import pickle

import pytest

from rllib_asor.cli import experiment, multi_agent
from rllib_asor.cli.errors import UsageError
from rllib_asor.registry import envs
from rllib_asor.registry.families import RACE

MULTI = """
x:
  env: game_env/ObstacleRaceMulti-v0
  run: PPO
  stop: {{training_iteration: 2}}
  config:
    env_config: {{num_racers: 2, max_episode_steps: 20}}
    multi_agent: {block}
    rl_module: {{module_class: race_net}}
"""


def test_shared_policy_block_maps_every_racer_to_one_policy(write_yaml):
    [exp] = experiment.load_file(
        write_yaml(MULTI.format(block="{policies: [shared], policy_mapping_fn: shared}"))
    )
    cfg = experiment.validate(exp)
    assert cfg.is_multi_agent and set(cfg.policies) == {"shared"}
    assert {cfg.policy_mapping_fn(f"racer_{i}", None) for i in range(4)} == {"shared"}
    # The Tune param space round-trips to a multi-agent config (what each trial rebuilds).
    from ray.rllib.algorithms.ppo import PPOConfig

    space = experiment.param_space(exp, cfg)
    again = PPOConfig().update_from_dict(space)
    assert again.is_multi_agent and set(again.policies) == {"shared"}
    assert again.policy_mapping_fn("racer_1", None) == "shared"


def test_mapping_to_a_policy_id_pickles_by_reference():
    fn = multi_agent.parse({"policies": ["shared"], "policy_mapping_fn": "shared"})[
        "policy_mapping_fn"
    ]
    assert pickle.loads(pickle.dumps(fn))("racer_0") == "shared"


def test_mapping_fn_may_be_a_function_path():
    kwargs = multi_agent.parse(
        {
            "policies": ["shared"],
            "policy_mapping_fn": "rllib_asor.race.config:shared_policy_mapping",
            "policies_to_train": ["shared"],
        }
    )
    assert kwargs["policy_mapping_fn"]("racer_3") == "shared"
    assert kwargs["policies_to_train"] == ["shared"]


@pytest.mark.parametrize(
    ("block", "fragment"),
    [
        ("{policies: shared, policy_mapping_fn: shared}", "multi_agent.policies='shared'"),
        ("{policies: [], policy_mapping_fn: shared}", "non-empty list of policy ids"),
        ("{policies: [a, a], policy_mapping_fn: a}", "must be unique"),
        ("{policies: [shared]}", "multi_agent.policy_mapping_fn is missing"),
        ("{policies: [shared], policy_mapping_fn: other}", "is not a policy id"),
        ("{policies: [shared], policy_mapping_fn: 'no.such:fn'}", "cannot be imported"),
        ("{policies: [shared], policy_mapping_fn: shared, foo: 1}", "multi_agent.foo is unknown"),
        (
            "{policies: [shared], policy_mapping_fn: shared, policies_to_train: [b]}",
            "'b' is not in policies",
        ),
        ("[shared]", "allowed a mapping"),
        (
            "{policies: {grid_search: [[a], [b]]}, policy_mapping_fn: a}",
            "grid_search is not allowed here",
        ),
    ],
)
def test_bad_multi_agent_block_is_refused_naming_the_key(write_yaml, block, fragment):
    [exp] = experiment.load_file(write_yaml(MULTI.format(block=block)))
    with pytest.raises(UsageError, match=r"x\.config\.multi_agent") as err:
        experiment.validate(exp)
    assert fragment in str(err.value)


def test_race_envs_are_known_to_the_cli_with_race_callbacks(write_yaml):
    assert envs.env_exists("game_env/ObstacleRaceMulti-v0")
    [exp] = experiment.load_file(
        write_yaml(
            "x:\n  env: game_env/ObstacleRace-v0\n  run: PPO\n  stop: {training_iteration: 2}\n"
        )
    )
    from rllib_asor.race.config import RaceMetricsCallback

    classes = experiment.validate(exp).callbacks_class
    assert RaceMetricsCallback in (classes if isinstance(classes, list) else [classes])


def test_race_callbacks_are_not_forced_over_the_files_own(write_yaml):
    [exp] = experiment.load_file(
        write_yaml(
            "x:\n  env: game_env/ObstacleRace-v0\n  run: PPO\n  stop: {training_iteration: 2}\n"
            "  config: {callbacks: ray.rllib.callbacks.callbacks.RLlibCallback}\n"
        )
    )
    from rllib_asor.race.config import RaceMetricsCallback

    classes = experiment.validate(exp).callbacks_class
    assert RaceMetricsCallback not in (classes if isinstance(classes, list) else [classes])


def test_single_race_env_gets_max_episode_steps_in_its_constructor():
    env = envs.make_env("game_env/ObstacleRace-v0", {"map_id": 0, "max_episode_steps": 3})
    env.reset(seed=0)
    done, info, n = False, {}, 0
    while not done:
        _, _, term, trunc, info = env.step(env.action_space.sample())
        done, n = term or trunc, n + 1
    env.close()
    assert n <= 3 and "episode_metrics" in info


def test_bad_race_env_config_is_refused_before_ray(write_yaml):
    [exp] = experiment.load_file(
        write_yaml(
            "x:\n  env: game_env/ObstacleRaceMulti-v0\n  run: PPO\n  stop: {training_iteration: 2}\n"
            "  config: {env_config: {num_racers: 0}}\n"
        )
    )
    with pytest.raises(UsageError, match=r"x\.config\.env_config: .*cannot be built"):
        experiment.validate(exp)


def test_test_mode_shortens_race_episodes_so_race_metrics_appear(write_yaml):
    [exp] = experiment.load_file(
        write_yaml(
            "x:\n  env: game_env/ObstacleRace-v0\n  run: PPO\n"
            "  config: {env_config: {map_id: 3, max_episode_steps: 1000}}\n"
        )
    )
    experiment.apply_overrides(exp, test=True)
    assert exp.config["env_config"] == {
        "map_id": 3,
        "max_episode_steps": RACE.test_env_config["max_episode_steps"],
    }
    assert (
        experiment.validate(exp).env_config["max_episode_steps"]
        == RACE.test_env_config["max_episode_steps"]
    )
