"""OverlappedPPO: the env runners sample batch k+1 while the Learner trains on batch k."""

from __future__ import annotations

import numpy as np
import pytest
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.algorithms.sac import SACConfig

import rllib_asor
from rllib_asor.algorithms.ppo.overlap import OverlappedPPO, overlap_sampling

TAG = "overlap_sample"


def _cartpole(runners: int = 1) -> PPOConfig:
    return (
        PPOConfig()
        .environment("CartPole-v1")
        .env_runners(num_env_runners=runners, num_envs_per_env_runner=2)
        .training(train_batch_size=400, minibatch_size=100, num_epochs=2)
        .debugging(seed=0)
    )


def _spy_in_flight(algo) -> list[int]:
    """From now on, per Learner update: the overlap's sample calls then in flight."""
    seen: list[int] = []
    update = algo.learner_group.update

    def spy(*args, **kwargs):
        seen.append(algo.env_runner_group.num_in_flight_async_reqs(TAG))
        return update(*args, **kwargs)

    algo.learner_group.update = spy
    return seen


def test_switched_off_it_is_plain_ppo(ray_session):
    algo = overlap_sampling(_cartpole(), enabled=False).build_algo()
    try:
        seen = _spy_in_flight(algo)
        for _ in range(3):
            result = algo.train()
        assert result["num_env_steps_sampled_lifetime"] >= 3 * 400
        assert seen == [0, 0, 0]
    finally:
        algo.stop()


def test_without_remote_runners_it_samples_in_the_driver(ray_session):
    algo = overlap_sampling(_cartpole(runners=0)).build_algo()
    try:
        assert algo.env_runner_group.num_remote_workers() == 0
        result = algo.train()
        assert result["num_env_steps_sampled_lifetime"] >= 400
    finally:
        algo.stop()


def test_samples_the_next_batch_during_the_update_learns_and_restores(ray_session, tmp_path):
    """The runners sample batch k+1 while the Learner trains on batch k (one sample call in
    flight at every update), the lag correction reports its lag, the policy learns CartPole,
    and a checkpoint restores."""
    config = _cartpole().training(train_batch_size=1000, minibatch_size=250, num_epochs=6, lr=1e-3)
    algo = overlap_sampling(config).build_algo()
    try:
        assert isinstance(algo, OverlappedPPO)
        seen = _spy_in_flight(algo)
        results = [algo.train() for _ in range(10)]
        assert seen == [1] * 10
        returns = [r["env_runners"]["episode_return_mean"] for r in results]
        assert np.nanmax(returns[-3:]) > 3 * returns[0]  # random policy ≈ 20
        # The lag correction (on by default) reports the lag it corrects: none in the first
        # batch (sampled by the weights it trains), one update of lag in every later one.
        lag = [r["learners"]["default_policy"] for r in results]
        assert lag[0]["lag/logp_gap"] == pytest.approx(0.0, abs=1e-5)
        assert lag[0]["lag/weight_mean"] == pytest.approx(1.0, abs=1e-5)
        assert all(r["lag/logp_gap"] > 1e-4 for r in lag[1:])
        assert all(0 < r["lag/weight_mean"] <= 1.0 for r in lag[1:])
        path = algo.save(str(tmp_path / "ckpt")).checkpoint.path
    finally:
        algo.stop()
    restored = OverlappedPPO.from_checkpoint(path)
    try:
        assert restored.train()["num_env_steps_sampled_lifetime"] > 10 * 1000
    finally:
        restored.stop()


def test_with_asor_accepts_the_overlapped_config(ray_session):
    config = rllib_asor.with_asor(
        overlap_sampling(PPOConfig().environment("rllib_asor/LavaWorld-v0"))
        .env_runners(num_env_runners=1, num_envs_per_env_runner=1)
        .training(train_batch_size=200, minibatch_size=100, num_epochs=1),
        seed=0,
    )
    algo = config.build_algo()
    try:
        assert isinstance(algo, OverlappedPPO)
        result = algo.train()
        result = algo.train()
        assert np.isfinite(result["asor"]["aug_reward_mean"])
    finally:
        algo.stop()


def test_only_ppo_configs_overlap():
    with pytest.raises(ValueError, match="needs a PPO config"):
        overlap_sampling(SACConfig().environment("Pendulum-v1"))
