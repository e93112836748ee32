"""RaceMetricsCallback on real RLlib episodes and MetricsLogger (no Ray, no env)."""

import numpy as np
import pytest
from ray.rllib.env.multi_agent_episode import MultiAgentEpisode
from ray.rllib.env.single_agent_episode import SingleAgentEpisode
from ray.rllib.utils.metrics.metrics_logger import MetricsLogger

from rllib_asor.race.config import RACE_METRICS, RaceMetricsCallback


def metrics(success: float) -> dict:
    return {
        "success": success,
        "trapped": 1.0 - success,
        "unnecessary_jump_rate": 0.25,
        "distance_from_cliff": 2.0,
        "goal_reward": 0.3 * success,
    }


def obs():
    return np.zeros(2, np.float32)


def test_single_agent_episode_logs_every_race_metric():
    ep = SingleAgentEpisode()
    ep.add_env_reset(observation=obs(), infos={"map_id": 0})
    ep.add_env_step(obs(), 0, -0.02, infos={"map_id": 0})
    ep.add_env_step(obs(), 0, 1.0, infos={"episode_metrics": metrics(1.0)}, terminated=True)
    logger = MetricsLogger()
    RaceMetricsCallback().on_episode_end(episode=ep, metrics_logger=logger, env_index=0)
    assert {k: logger.peek(("race", k)) for k in RACE_METRICS} == {
        "success_rate": 1.0,
        "trapped_rate": 0.0,
        "unnecessary_jump_rate": 0.25,
        "distance_from_cliff": 2.0,
        "goal_reward": pytest.approx(0.3),
    }


def test_racer_that_finished_in_an_earlier_chunk_is_counted_once():
    ep = MultiAgentEpisode()
    both = ("racer_0", "racer_1")
    ep.add_env_reset(observations={a: obs() for a in both}, infos={a: {} for a in both})
    ep.add_env_step(
        observations={a: obs() for a in both},
        actions={a: 0 for a in both},
        rewards={a: 0.0 for a in both},
        infos={"racer_0": {"episode_metrics": metrics(1.0)}, "racer_1": {}},
        terminateds={"racer_0": True, "__all__": False},
        truncateds={"__all__": False},
    )
    last = ep.cut()  # racer_0 (done) is only in the first chunk
    last.add_env_step(
        observations={"racer_1": obs()},
        actions={"racer_1": 0},
        rewards={"racer_1": 0.0},
        infos={"racer_1": {"episode_metrics": metrics(0.0)}},
        terminateds={"__all__": False},
        truncateds={"racer_1": True, "__all__": True},
    )
    assert set(last.agent_episodes) == {"racer_1"}
    logger = MetricsLogger()
    RaceMetricsCallback().on_episode_end(
        episode=last, prev_episode_chunks=[ep], metrics_logger=logger, env_index=0
    )
    assert logger.peek(("race", "success_rate")) == 0.5
    assert logger.peek(("race", "trapped_rate")) == 0.5
    assert logger.peek(("race", "goal_reward")) == pytest.approx(0.15)


def test_train_result_gets_race_block_with_policy_entropy():
    result = {
        "env_runners": {"race": {"success_rate": 0.5}},
        "learners": {"shared": {"entropy": 7.5}, "asor_disc.shared": {"disc_loss": 0.7}},
    }
    RaceMetricsCallback().on_train_result(result=result)
    assert result["race"] == {"success_rate": 0.5, "policy_entropy": 7.5}
    result = {"learners": {"a": {"entropy": 1.0}, "b": {"entropy": 3.0}}}
    RaceMetricsCallback().on_train_result(result=result)
    assert result["race"] == {
        "policy_entropy": 2.0,
        "a/policy_entropy": 1.0,
        "b/policy_entropy": 3.0,
    }


def test_per_map_metrics_and_lifetime_totals():
    logger = MetricsLogger()
    for map_id, success in ((3, 1.0), (3, 0.0), (5, 1.0)):
        ep = SingleAgentEpisode()
        ep.add_env_reset(observation=obs(), infos={"map_id": map_id})
        ep.add_env_step(
            obs(),
            0,
            1.0,
            infos={"map_id": map_id, "episode_metrics": metrics(success)},
            terminated=True,
        )
        RaceMetricsCallback().on_episode_end(episode=ep, metrics_logger=logger, env_index=0)
    assert logger.peek(("race", "map_3", "success_rate")) == 0.5
    assert logger.peek(("race", "map_3", "episodes")) == 2
    assert logger.peek(("race", "map_3", "success_sum")) == 1
    assert logger.peek(("race", "map_3", "goal_reward_sum")) == pytest.approx(0.3)
    assert logger.peek(("race", "map_5", "success_rate")) == 1.0
    assert logger.peek(("race", "success_rate")) == pytest.approx(2 / 3)


def test_returned_chunks_keep_reward_terms_and_metrics_only_in_each_racers_last_info():
    def info(t: int) -> dict:
        return {"map_id": 3, "dynamics_id": 3, "reward_terms": {"goal": 0.1 * t},
                "episode_metrics": metrics(float(t == 3))}  # fmt: skip

    ep = SingleAgentEpisode()
    ep.add_env_reset(observation=obs(), infos=info(0))
    for t in (1, 2, 3):
        ep.add_env_step(obs(), 0, 0.0, infos=info(t), terminated=t == 3)
    shared = ep.get_infos(1)  # a dict the runner's own continuing episode may still hold
    multi = MultiAgentEpisode()
    multi.add_env_reset(observations={"racer_0": obs()}, infos={"racer_0": info(0)})
    multi.add_env_step(observations={"racer_0": obs()}, actions={"racer_0": 0},
                       rewards={"racer_0": 0.0}, infos={"racer_0": info(1)})  # fmt: skip
    RaceMetricsCallback().on_sample_end(samples=[ep, multi])
    infos = ep.get_infos()
    assert [sorted(i) for i in infos[:-1]] == [["dynamics_id", "map_id"]] * 3
    assert infos[-1] == info(3)  # the last: what `_last_info` and evaluation summaries read
    assert "episode_metrics" in shared  # slimmed as new dicts, the old ones left alone
    racer = multi.agent_episodes["racer_0"].get_infos()
    assert sorted(racer[0]) == ["dynamics_id", "map_id"] and racer[-1] == info(1)
    logger = MetricsLogger()  # the metrics still come from the kept last info
    RaceMetricsCallback().on_episode_end(episode=ep, metrics_logger=logger, env_index=0)
    assert logger.peek(("race", "success_rate")) == 1.0
