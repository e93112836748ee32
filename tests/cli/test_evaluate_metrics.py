"""`rllib evaluate` reports the env's own episode metrics (race success, lava is_success)."""

import gymnasium as gym
import pytest
from ray.rllib.env.single_agent_episode import SingleAgentEpisode

import game_env  # noqa: F401  (registers game_env/ObstacleRace-v0)
import rllib_asor.envs  # noqa: F401
from rllib_asor.evaluation.summary import episode_metrics


def _episode(env_id: str, seed: int, **kwargs) -> SingleAgentEpisode:
    env = gym.make(env_id, **kwargs)
    env.action_space.seed(seed)
    obs, info = env.reset(seed=seed)
    ep = SingleAgentEpisode(
        observations=[obs],
        infos=[info],
        observation_space=env.observation_space,
        action_space=env.action_space,
    )
    done = False
    while not done:
        action = env.action_space.sample()
        obs, reward, term, trunc, info = env.step(action)
        ep.add_env_step(obs, action, reward, infos=info, terminated=term, truncated=trunc)
        done = term or trunc
    return ep


def test_race_episode_metrics_are_averaged_over_episodes():
    eps = [_episode("game_env/ObstacleRace-v0", s, max_episode_steps=40) for s in (0, 1)]
    metrics = episode_metrics(eps)
    for key in ("success", "trapped", "unnecessary_jump_rate", "goal_reward"):
        assert key in metrics
    last = [ep.get_infos(-1)["episode_metrics"]["total_reward"] for ep in eps]
    assert metrics["total_reward"] == pytest.approx(sum(last) / 2)


def test_lava_is_success_becomes_the_success_rate():
    eps = [_episode("rllib_asor/LavaWorld-v0", s) for s in range(3)]
    expected = sum(bool(ep.get_infos(-1)["is_success"]) for ep in eps) / 3
    assert episode_metrics(eps) == {"success": pytest.approx(expected)}


def test_envs_without_metrics_report_none():
    assert episode_metrics([_episode("CartPole-v1", 0)]) == {}
