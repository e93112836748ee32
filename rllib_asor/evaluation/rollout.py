"""Deterministic rollouts of an RLModule on a gymnasium env, one episode at a time.

Used by the offline scorer (`rllib_asor.data.scoring`) and the MuJoCo shift benchmark: the
policy's deterministic action (SAC/CQL: the squashed mean; PPO: the Gaussian mean), optionally
on transformed observations (`obs_fn`, e.g. a frozen MeanStdFilter) and mapped onto the env's
action space (`action_fn`, e.g. unsquash or clip).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from rllib_asor import ray_compat as compat

Transform = Callable[[np.ndarray], np.ndarray]


def deterministic_action(module: Any, obs: np.ndarray) -> np.ndarray:
    """The module's deterministic action for one observation."""
    import torch
    from ray.rllib.core import Columns

    from rllib_asor.devices import module_device

    x = torch.as_tensor(obs, dtype=torch.float32, device=module_device(module))[None]
    with torch.no_grad():
        out = module.forward_inference({Columns.OBS: x})
        dist = module.get_inference_action_dist_cls().from_logits(out[Columns.ACTION_DIST_INPUTS])
        return deterministic_sample(dist)[0].cpu().numpy()


def deterministic_sample(dist: Any) -> Any:
    """The distribution's mode as an action. For RLlib's squashed Gaussian (SAC, CQL) that is
    the squashed mean tanh(μ): RLlib 2.60's `TorchSquashedGaussian.to_deterministic()` returns μ
    *before* the tanh (the env runner then clips it), an action the policy never samples."""
    from ray.rllib.core.distribution.torch.torch_distribution import TorchSquashedGaussian

    if isinstance(dist, TorchSquashedGaussian):
        return compat.squash(dist, dist.loc)
    return dist.to_deterministic().sample()


def unsquash(low: np.ndarray, high: np.ndarray) -> Transform:
    """[-1, 1] → [low, high] and clipped (RLlib's unsquash of SAC/CQL actions)."""
    return lambda a: np.clip(low + (a + 1.0) * (high - low) / 2.0, low, high)


def clip(low: np.ndarray, high: np.ndarray) -> Transform:
    """Clipped to [low, high] (what RLlib's env runner does with PPO's Gaussian actions)."""
    return lambda a: np.clip(a, low, high)


def rollout(
    module: Any,
    env_id: str,
    episodes: int,
    *,
    seed: int = 0,
    env_kwargs: Mapping[str, Any] | None = None,
    obs_fn: Transform | None = None,
    action_fn: Callable[[np.ndarray, np.ndarray], Transform] = clip,
) -> tuple[list[float], list[int]]:
    """Undiscounted returns and lengths of `episodes` deterministic episodes (reset seeds
    seed, seed + 1, ...); `action_fn(low, high)` maps actions onto the env's bounds."""
    import gymnasium as gym

    import rllib_asor.envs  # noqa: F401  (registers our env ids in this process)

    env = gym.make(env_id, **dict(env_kwargs or {}))
    to_env = action_fn(env.action_space.low, env.action_space.high)
    returns, lengths = [], []
    try:
        for i in range(episodes):
            obs, _ = env.reset(seed=seed + i)
            done, total, n = False, 0.0, 0
            while not done:
                action = deterministic_action(module, obs if obs_fn is None else obs_fn(obs))
                obs, r, term, trunc, _ = env.step(to_env(action))
                total, n, done = total + float(r), n + 1, term or trunc
            returns.append(total)
            lengths.append(n)
    finally:
        env.close()
    return returns, lengths
