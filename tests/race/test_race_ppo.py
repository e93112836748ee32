"""PPO+ASOR on the obstacle race through real RLlib: one iteration, single and 2 racers."""

import math

import numpy as np
import pytest
import torch

import rllib_asor
from rllib_asor.race.config import (
    MULTI_ENV,
    RACE_ASOR_OBS_KEYS,
    RACE_METRICS,
    SHARED_POLICY,
    RaceMetricsCallback,
    make_multi_race_env,
    make_single_race_env,
    race_ppo_config,
)
from rllib_asor.rllib.callbacks import AsorMetricsCallback

ASOR_KEYS = ("disc_loss", "disc_acc", "aug_reward_mean", "real_fraction", "rnd_loss", "lambda")


@pytest.fixture(autouse=True, scope="module")
def one_torch_thread():
    """Local mode runs the env runner in this process: 2 torch threads on 2 busy cores made
    a batch-1 forward pass 40× slower (remote env runners get OMP_NUM_THREADS=1 from Ray)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def tiny_race_ppo(num_racers, obs_keys):
    config = (
        race_ppo_config(num_racers=num_racers, map_id=0, max_episode_steps=40)
        .env_runners(num_env_runners=0)
        .training(train_batch_size=200, minibatch_size=100, num_epochs=1)
        .debugging(seed=0)
    )
    return rllib_asor.with_asor(config, lambda_=0.01, obs_keys=obs_keys, seed=0)


def check_result(result, policy):
    asor = result["asor"]
    for key in ASOR_KEYS:
        assert math.isfinite(asor[key]), key
    bound = 2.0 * 3.0 * asor["lambda"] + 1e-6  # potential form, bonus clipped to ±3
    assert -bound <= asor["aug_reward_min"] <= asor["aug_reward_max"] <= bound
    race = result["race"]
    per_map = {k: v for k, v in race.items() if k.startswith("map_")}
    assert set(race) - set(per_map) == {*RACE_METRICS, "policy_entropy"}
    assert per_map and all(
        set(v) == {"success_rate", "goal_reward", "episodes", "success_sum", "goal_reward_sum"}
        for v in per_map.values()
    )
    assert sum(v["episodes"] for v in per_map.values()) >= 4
    assert race["policy_entropy"] == pytest.approx(result["learners"][policy]["entropy"])
    assert 0.0 <= race["success_rate"] <= 1.0 and 0.0 <= race["trapped_rate"] <= 1.0
    assert 0.0 <= race["unnecessary_jump_rate"] <= 1.0 and race["distance_from_cliff"] >= 0.0
    # 200 steps of 40-step episodes: at least 4 racer-episodes ended and were counted.
    assert result["env_runners"]["num_episodes"] >= 4


def test_single_racer_ppo_asor_iteration_reports_asor_and_race_metrics(ray_session):
    config = tiny_race_ppo(1, RACE_ASOR_OBS_KEYS)
    assert config.callbacks_class == [RaceMetricsCallback, AsorMetricsCallback]
    algo = config.build_algo()
    try:
        module = algo.learner_group._learner.module
        assert set(module.keys()) == {"default_policy", "asor_disc.default_policy"}
        assert type(module["default_policy"]).__name__ == "RaceNetModule"
        # The discriminator and RND see agent (32) + destination (9).
        assert module["asor_disc.default_policy"].feature_dim == 32 + 9
        check_result(algo.train(), "default_policy")
    finally:
        algo.stop()


def test_two_racers_share_one_policy_and_report_asor_and_race_metrics(ray_session):
    config = tiny_race_ppo(2, ["agent", "destination", "goals"])
    assert config.env == MULTI_ENV and set(config.policies) == {SHARED_POLICY}
    algo = config.build_algo()
    try:
        module = algo.learner_group._learner.module
        # A grid key works too: agent (32) + destination (9) + goals (3·16·16).
        assert module[f"asor_disc.{SHARED_POLICY}"].feature_dim == 32 + 9 + 768
        assert set(module.keys()) == {SHARED_POLICY, f"asor_disc.{SHARED_POLICY}"}
        result = algo.train()
        check_result(result, SHARED_POLICY)
        # Both racers' steps were sampled for the one shared module.
        assert result["env_runners"]["num_agent_steps_sampled"].keys() == {"racer_0", "racer_1"}
    finally:
        algo.stop()


def test_single_env_creator_passes_max_episode_steps_to_the_env():
    env = make_single_race_env({"map_id": 0, "max_episode_steps": 5})
    env.reset(seed=0)
    steps, terminated, truncated = 0, False, False
    while not (terminated or truncated):
        _, _, terminated, truncated, info = env.step(env.action_space.sample())
        steps += 1
    assert (terminated and steps <= 5) or (truncated and steps == 5)
    assert set(info["episode_metrics"]) >= {"success", "trapped", "goal_reward"}
    env.close()


def test_multi_env_creator_renders_without_a_mode_and_gives_each_racer_metrics():
    env = make_multi_race_env({"num_racers": 2, "map_id": 0, "max_episode_steps": 3})
    assert env.render() is None  # no render_mode: PettingZoo's render() takes no mode
    obs, _ = env.reset(seed=0)
    assert set(obs) == {"racer_0", "racer_1"}
    assert env.observation_space["racer_0"]["agent"].shape == (32,)
    done = {"__all__": False}
    while not done["__all__"]:
        actions = {a: env.action_space[a].sample() for a in obs}
        obs, _, done, trunc, infos = env.step(actions)
        done = {"__all__": done["__all__"] or trunc["__all__"]}
    assert all("episode_metrics" in infos[a] for a in infos)
    assert np.isfinite([infos[a]["episode_metrics"]["distance_from_cliff"] for a in infos]).all()
    env.close()


def test_race_ppo_config_rejects_bad_num_racers():
    with pytest.raises(ValueError, match="num_racers"):
        race_ppo_config(num_racers=0)
