"""Deterministic rollouts of ESCP (or any SAC-style) modules, with ESCP's inference window.

ESCP evaluates with the policy's deterministic action tanh(μ) (`Policy.inference_one_step`,
`deterministic=True`) and no noise on z (`set_deterministic_ep(True)`), the encoder re-run over
the last H steps of (s, a_prev), zero-padded before the episode start. `rollout` does that
for an `EscpTorchRLModule`, and for other SAC modules (no window) takes tanh(μ) of their
inference output too, so both are evaluated alike. It can record z at every step (the
encoder evidence, benchmarks/escp_encoder.py).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from ray.rllib.core.columns import Columns

from rllib_asor.algorithms.escp.module import EscpTorchRLModule
from rllib_asor.algorithms.escp.replay import WINDOW
from rllib_asor.devices import module_device


@dataclass
class Rollouts:
    """Per episode: return, length; per step (when recorded): z and info["dynamics_id"]."""

    returns: list[float] = field(default_factory=list)
    lengths: list[int] = field(default_factory=list)
    contexts: list[np.ndarray] = field(default_factory=list)
    dynamics_ids: list[np.ndarray] = field(default_factory=list)


@torch.no_grad()
def rollout(
    module: Any,
    env_id: str,
    episodes: int,
    *,
    seed: int = 0,
    env_kwargs: Mapping[str, Any] | None = None,
    record_context: bool = False,
) -> Rollouts:
    """`episodes` deterministic episodes (reset seeds seed, seed + 1, ...)."""
    import gymnasium as gym

    import rllib_asor.envs  # noqa: F401  (registers our env ids)

    module = module.unwrapped() if hasattr(module, "unwrapped") else module
    escp = isinstance(module, EscpTorchRLModule)
    env = gym.make(env_id, **dict(env_kwargs or {}))
    low, high = env.action_space.low, env.action_space.high
    out = Rollouts()
    h = module.escp.history_len if escp else 0
    device = module_device(module)
    try:
        for i in range(episodes):
            obs, info = env.reset(seed=seed + i)
            win = np.zeros((h, obs.shape[0] + low.shape[0]), np.float32) if escp else None
            last_action = np.zeros(low.shape[0], np.float32)
            done, total, n, zs, ids = False, 0.0, 0, [], []
            while not done:
                x = torch.as_tensor(obs, dtype=torch.float32, device=device)[None]
                batch = {Columns.OBS: x}
                if escp:
                    win = np.roll(win, -1, axis=0)
                    win[-1] = np.concatenate([obs, last_action])
                    batch[WINDOW] = torch.as_tensor(win, device=device)[None]
                    if record_context:
                        zs.append(module.context(batch[WINDOW])[0].cpu().numpy())
                        ids.append(int(info.get("dynamics_id", -1)))
                logits = module.forward_inference(batch)[Columns.ACTION_DIST_INPUTS]
                action = torch.tanh(logits.chunk(2, dim=-1)[0])[0].cpu().numpy()
                obs, r, term, trunc, info = env.step(low + (action + 1.0) * (high - low) / 2.0)
                last_action = action.astype(np.float32)
                total, n, done = total + float(r), n + 1, term or trunc
            out.returns.append(total)
            out.lengths.append(n)
            if record_context and escp:
                out.contexts.append(np.asarray(zs))
                out.dynamics_ids.append(np.asarray(ids))
    finally:
        env.close()
    return out
