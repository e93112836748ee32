"""ASOR beyond single-agent PPO: SAC (continuous + discrete, both proxies) and multi-agent PPO."""

import numpy as np
import pytest
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.examples.envs.classes.multi_agent import MultiAgentCartPole
from ray.tune.registry import register_env

import rllib_asor


def sac_config(env):
    return (
        SACConfig()
        .environment(env)
        .env_runners(num_env_runners=0)
        .training(
            train_batch_size_per_learner=64,
            num_steps_sampled_before_learning_starts=64,
            replay_buffer_config={"type": "PrioritizedEpisodeReplayBuffer", "capacity": 5000},
        )
        .reporting(min_sample_timesteps_per_iteration=64)
        .debugging(seed=0)
    )


@pytest.mark.parametrize(
    ("env", "proxy"),
    [
        # ~20 s, `make test-slow`: the ensemble proxy's training and scores are
        # tests/asor/test_proxy_behaviour.py's, SAC+ASOR on Pendulum test_many_learners[sac].
        pytest.param("Pendulum-v1", "ensemble", marks=pytest.mark.slow),
        ("CartPole-v1", "rnd"),
    ],
)
def test_sac_asor_update_trains_aux_and_values_come_from_critics(ray_session, env, proxy):
    algo = rllib_asor.with_asor(sac_config(env), lambda_=0.05, proxy=proxy).build_algo()
    try:
        for _ in range(2):  # one update at the end of the first, 64 in the second
            result = algo.train()
        asor = result["asor"]
        assert asor["real_fraction"] == pytest.approx(0.25, abs=0.02)
        # Potential shaping (next states from the replayed transitions), bounded by
        # (1 + γ)·λ·bonus_clip with λ already × the reward scale; two-signed.
        assert asor["potential"] == 1.0
        bound = 2.0 * 3.0 * asor["lambda"] + 1e-6
        assert -bound <= asor["aug_reward_min"] <= asor["aug_reward_max"] <= bound
        assert np.isfinite(asor["disc_loss"]) and np.isfinite(asor[f"{proxy}_loss"])
        # V(s) = min Q(s, π(s)): Pendulum's returns are negative, CartPole's positive.
        assert (asor["value_mean"] < 0) == (env == "Pendulum-v1")
        learner = algo.learner_group._learner
        assert {"asor_disc.default_policy"} <= set(
            learner.module.keys()
        )
    finally:
        algo.stop()


def test_multi_agent_ppo_gets_one_discriminator_per_trained_policy(ray_session):
    register_env("ma_cartpole", lambda cfg: MultiAgentCartPole({"num_agents": 2}))
    config = (
        PPOConfig()
        .environment("ma_cartpole")
        .env_runners(num_env_runners=0)
        .multi_agent(
            policies={"p0", "p1"},
            policy_mapping_fn=lambda aid, *a, **k: f"p{aid}",
            policies_to_train=["p0"],
        )
        .training(train_batch_size=256, minibatch_size=64, num_epochs=1)
    )
    algo = rllib_asor.with_asor(config, lambda_=0.05).build_algo()
    try:
        modules = set(algo.learner_group._learner.module.keys())
        assert modules == {"p0", "p1", "asor_disc.p0"}
        result = algo.train()
        # Only p0 is regularised: one discriminator, so asor/... is flat (not keyed by policy).
        assert set(result["asor"]) >= {"disc_loss", "aug_reward_mean", "rnd_loss"}
        assert not any(isinstance(v, dict) for v in result["asor"].values())
    finally:
        algo.stop()
