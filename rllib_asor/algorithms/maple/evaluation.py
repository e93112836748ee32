"""MAPLE's policy in the real env, stepping its GRU context (`maple_st.py test_one_trail`).

Deterministic actions (tanh of the mean), the hidden state and the last action carried from
step to step, zero at each reset; D4RL-normalised with the dataset's own reference returns
(`rllib_asor.data.scoring.normalized_score`), per dynamics and averaged over them, as the paper.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch

from rllib_asor.algorithms.maple.networks import MapleNetworks
from rllib_asor.data.scoring import normalized_score
from rllib_asor.devices import module_device


def episode_returns(
    nets: MapleNetworks, env_id: str, dynamics: str, episodes: int, seed: int = 0
) -> list[float]:
    """Undiscounted returns of `episodes` deterministic episodes (reset seeds seed, seed+1, ...)."""
    import gymnasium as gym

    import rllib_asor.envs  # noqa: F401  (registers our env ids)

    env = gym.make(env_id, dynamics=dynamics)
    low, high = env.action_space.low, env.action_space.high
    returns, device = [], module_device(nets)
    try:
        for i in range(episodes):
            obs, _ = env.reset(seed=seed + i)
            hidden = torch.zeros(1, nets.gru_hidden, device=device)
            last = torch.zeros(1, nets.action_dim, device=device)
            done, total = False, 0.0
            while not done:
                o = torch.as_tensor(obs, dtype=torch.float32, device=device)[None]
                act, hidden = nets.policy_step(o, last, hidden, deterministic=True)
                a = np.clip(low + (act[0].cpu().numpy() + 1.0) * (high - low) / 2.0, low, high)
                obs, r, term, trunc, _ = env.step(a)
                total, done, last = total + float(r), term or trunc, act
            returns.append(total)
    finally:
        env.close()
    return returns


def evaluate(
    nets: MapleNetworks,
    manifest: Mapping[str, Any],
    *,
    dynamics: Sequence[str] | None = None,
    episodes: int = 5,
    seed: int = 0,
) -> dict[str, dict[str, float]]:
    """Per dynamics `return_mean`, `return_std`, `normalized_score`, plus their `mean`
    (the shape of `rllib_asor.data.scoring.evaluate`)."""
    out: dict[str, dict[str, float]] = {}
    was_training = nets.training
    nets.eval()
    try:
        for dyn in dynamics or tuple(manifest["datasets"]):
            rets = episode_returns(nets, manifest["env"], dyn, episodes, seed)
            try:
                score = normalized_score(float(np.mean(rets)), manifest["task"], manifest, dyn)
            except ValueError:  # the dataset has no random/expert reference returns
                score = float("nan")
            out[dyn] = {
                "return_mean": float(np.mean(rets)),
                "return_std": float(np.std(rets)),
                "normalized_score": score,
            }
    finally:
        nets.train(was_training)
    if out:
        out["mean"] = {
            k: float(np.mean([v[k] for v in out.values()]))
            for k in ("return_mean", "normalized_score")
        }
    return out
