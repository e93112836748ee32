"""ESCP and ESCP+ASOR on RLlib: a user's own env with info["dynamics_id"], one update each,
no RL gradient into the encoder, a bit-exact checkpoint round trip, clear errors."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
import torch

from rllib_asor import EscpConfig, with_asor
from rllib_asor.algorithms.escp.learner import ENCODER_OPTIMIZER
from rllib_asor.algorithms.escp.module import CONTEXT


class GainEnv(gym.Env):
    """A user's env: a 1-d point whose action gain depends on the task (3 tasks)."""

    GAINS = (-1.0, 0.3, 2.0)

    def __init__(self, config: dict | None = None) -> None:
        self.observation_space = gym.spaces.Box(-10, 10, (2,), np.float32)
        self.action_space = gym.spaces.Box(-1, 1, (1,), np.float32)
        self._rng = np.random.default_rng((config or {}).get("seed", 0))
        self.report_id = (config or {}).get("report_id", True)

    def _obs(self) -> np.ndarray:
        return np.array([self.x, self.t / 20], np.float32)

    def _info(self) -> dict:
        return {"dynamics_id": 100 + self.task} if self.report_id else {}

    def reset(self, *, seed=None, options=None):
        self.task, self.x, self.t = int(self._rng.integers(3)), 1.0, 0
        return self._obs(), self._info()

    def step(self, action):
        self.x = float(np.clip(self.x + self.GAINS[self.task] * float(action[0]) * 0.2, -10, 10))
        self.t += 1
        return self._obs(), -abs(self.x), False, self.t >= 20, self._info()


def _config(**env_config) -> EscpConfig:
    return (
        EscpConfig()
        .environment(GainEnv, env_config=env_config)
        .env_runners(num_env_runners=0)
        .escp(history_len=4, rmdm_min_replay=0)
        .training(num_steps_sampled_before_learning_starts=64, train_batch_size_per_learner=32)
        .reporting(min_sample_timesteps_per_iteration=64)
        .debugging(seed=0)
    )


def _module(algo):
    return algo.learner_group._learner.module["default_policy"].unwrapped()


def test_escp_update_trains_encoder_by_rmdm_and_policy(ray_session) -> None:
    algo = _config().build_algo()
    try:
        algo.train()
        before = {k: v.clone() for k, v in _module(algo).state_dict().items()}
        result = algo.train()
        stats = result["learners"]["default_policy"]
        assert stats["escp_rmdm_on"] == 1.0 and stats["escp_batch_tasks"] >= 2
        assert math.isfinite(stats["qf_loss"]) and math.isfinite(stats["escp_rmdm_loss"])
        after = _module(algo).state_dict()
        for prefix in ("encoder.", "pi.", "qf."):
            assert any(
                not torch.equal(before[k], after[k]) for k in after if k.startswith(prefix)
            ), prefix
        assert sorted(_module(algo).task_ids[:3].tolist()) == [100, 101, 102]
        assert _module(algo).task_seen[:3].all()
    finally:
        algo.stop()


def test_no_rl_gradient_reaches_the_encoder(ray_session) -> None:
    algo = _config().build_algo()
    try:
        algo.train()
        learner = algo.learner_group._learner
        module = _module(algo)
        batch = algo.local_replay_buffer.sample(32)[0].columns
        batch = {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in batch.items()}
        fwd = module.forward_train(batch)
        learner.compute_loss_for_module(
            module_id="default_policy",
            config=learner.config.get_config_for_module("default_policy"),
            batch=batch,
            fwd_out=fwd,
        )
        losses = {k[1]: v for k, v in learner._temp_losses.items()}
        learner._temp_losses.clear()
        module.zero_grad(set_to_none=True)
        for name in ("qf_loss", "qf_twin_loss", "policy_loss", "alpha_loss"):
            losses[name].backward(retain_graph=True)
        assert all(p.grad is None for p in module.encoder.parameters())
        assert any(p.grad is not None for p in module.pi.parameters())
        module.zero_grad(set_to_none=True)
        losses[ENCODER_OPTIMIZER + "_loss"].backward()
        assert any(
            p.grad is not None and p.grad.abs().sum() > 0 for p in module.encoder.parameters()
        )
        assert all(p.grad is None for p in module.pi.parameters())
        assert fwd[CONTEXT].requires_grad
    finally:
        algo.stop()


def test_escp_asor_update_gives_finite_asor_metrics(ray_session) -> None:
    algo = with_asor(_config(), seed=0).build_algo()
    try:
        for _ in range(2):
            result = algo.train()
        asor = result["asor"]
        assert {"disc_loss", "lambda", "aug_reward_mean"} <= set(asor)
        # critic_ev is NaN until the critic's explained variance can be measured
        finite = {k: v for k, v in asor.items() if k != "critic_ev"}
        assert all(math.isfinite(float(v)) for v in finite.values()), finite
        assert result["learners"]["default_policy"]["escp_rmdm_on"] == 1.0
    finally:
        algo.stop()


def test_checkpoint_round_trip_is_bit_exact(ray_session, tmp_path) -> None:
    algo = _config().build_algo()
    try:
        algo.train()
        algo.train()
        algo.save_to_path(str(tmp_path))
        state = {k: v.clone() for k, v in _module(algo).state_dict().items()}
    finally:
        algo.stop()
    fresh = _config().debugging(seed=7).build_algo()
    try:
        fresh.restore_from_path(str(tmp_path))
        restored = _module(fresh).state_dict()
        assert set(restored) == set(state)
        for k, v in state.items():
            assert torch.equal(restored[k], v), k
        assert _module(fresh).task_seen.sum() == 3  # RMDM's moving averages and task table
        runner = fresh.env_runner.module.unwrapped()
        for k, v in runner.encoder.state_dict().items():
            assert torch.equal(v, state["encoder." + k])
    finally:
        fresh.stop()


def test_env_without_dynamics_id_fails_with_a_clear_message(ray_session) -> None:
    algo = _config(report_id=False).build_algo()
    try:
        with pytest.raises(ValueError, match="int `dynamics_id` in the info dict"):
            algo.train()
    finally:
        algo.stop()


def test_bad_settings_name_key_value_and_allowed() -> None:
    with pytest.raises(ValueError, match=r"escp.context_noise=-1 .*number ≥ 0"):
        EscpConfig().escp(context_noise=-1)
    with pytest.raises(ValueError, match=r"n_step=3 is not allowed for ESCP; expected 1"):
        EscpConfig().environment(GainEnv).training(n_step=3).validate()
