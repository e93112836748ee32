"""Shared pieces of the cluster / fault tests: a small PPO+ASOR lava config and result checks."""

from __future__ import annotations

from typing import Any

import numpy as np
from ray.rllib.algorithms.ppo import PPOConfig

import rllib_asor
import rllib_asor.envs  # noqa: F401  (registers rllib_asor/LavaWorld-v0)
from rllib_asor.registry.env_names import register_env

LAVA = "rllib_asor/LavaWorld-v0"
ASOR_KEYS = ("disc_loss", "disc_acc", "aug_reward_mean", "real_fraction", "rnd_loss")
RESTART_DEADLINE_S = 180
"""How long a test trains while it waits for a restarted runner: a new Ray worker imports torch
and RLlib first, which took over 60 s on the 2-core machine loaded with two other jobs (a
restart that never comes still fails the test)."""


def lava_ppo_asor(env: str = LAVA, env_config: dict | None = None, **runners: Any) -> Any:
    """PPO+ASOR on the lava world, 2 remote EnvRunners, tiny batches (seconds per iteration).

    Call it after `ray.init`: a gymnasium id of ours is registered with Tune (as `rllib train`
    does) so that remote EnvRunners, which never imported `rllib_asor.envs`, can build it.
    """
    if env == LAVA:
        register_env(LAVA)
    config = (
        PPOConfig()
        .environment(env, env_config=env_config or {})
        .env_runners(num_env_runners=2, num_envs_per_env_runner=1, num_cpus_per_env_runner=0.5,
                     **runners)
        .training(train_batch_size=200, minibatch_size=100, num_epochs=1, lr=1e-3)
        .rl_module(model_config={"fcnet_hiddens": [32, 32]})
        .debugging(seed=0)
    )
    return rllib_asor.with_asor(config, lambda_=0.1, seed=0)


def assert_asor_metrics(result: dict) -> None:
    """The iteration produced finite ASOR metrics and sampled env steps."""
    asor = result.get("asor") or {}
    for key in ASOR_KEYS:
        assert key in asor and np.isfinite(asor[key]), (key, sorted(asor))
    assert result["env_runners"]["num_env_steps_sampled"] > 0
