"""ESCP's evaluation: its policy as an actor of `rllib_asor.evaluation.rollout`.

ESCP evaluates with the policy's deterministic action tanh(μ) (`Policy.inference_one_step`,
`deterministic=True`) and no noise on z (`set_deterministic_ep(True)`), the encoder re-run over
the last H steps of (s, a_prev), zero-padded before the episode start. `EscpActor` keeps that
window for an `EscpTorchRLModule` (other SAC modules, no window: tanh(μ) of their inference
output too, so both are evaluated alike) and can record z at every step (the encoder evidence,
benchmarks/escp_encoder.py). `rollout` runs it through the project's one episode loop.
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
from rllib_asor.evaluation import rollout as loop
from rllib_asor.evaluation.rollout import Step


@dataclass
class Rollouts(loop.Rollouts):
    """`evaluation.rollout.Rollouts`, and per step (when recorded): z and info["dynamics_id"]."""

    contexts: list[np.ndarray] = field(default_factory=list)
    dynamics_ids: list[np.ndarray] = field(default_factory=list)


class EscpActor:
    """A fresh ESCP step per episode (call it); with `record_context`, z and the dynamics id
    of every step go to `contexts` / `dynamics_ids` (one list per episode)."""

    def __init__(self, module: Any, record_context: bool = False) -> None:
        self.module = module.unwrapped() if hasattr(module, "unwrapped") else module
        self.escp = isinstance(self.module, EscpTorchRLModule)
        self.record = record_context and self.escp
        self.contexts: list[list[np.ndarray]] = []
        self.dynamics_ids: list[list[int]] = []

    def __call__(self) -> Step:
        module, device = self.module, module_device(self.module)
        h = module.escp.history_len if self.escp else 0
        zs: list[np.ndarray] = []
        ids: list[int] = []
        if self.record:
            self.contexts.append(zs)
            self.dynamics_ids.append(ids)
        state: dict[str, np.ndarray] = {}

        @torch.no_grad()
        def step(obs: np.ndarray, info: Mapping[str, Any]) -> np.ndarray:
            batch = {Columns.OBS: torch.as_tensor(obs, dtype=torch.float32, device=device)[None]}
            if self.escp:
                if not state:  # the episode's first step: an all-zero window and last action
                    n = module.action_space.shape[0]
                    state["win"] = np.zeros((h, obs.shape[0] + n), np.float32)
                    state["last"] = np.zeros(n, np.float32)
                win = np.roll(state["win"], -1, axis=0)
                win[-1] = np.concatenate([obs, state["last"]])
                state["win"] = win
                batch[WINDOW] = torch.as_tensor(win, device=device)[None]
                if self.record:
                    zs.append(module.context(batch[WINDOW])[0].cpu().numpy())
                    ids.append(int(info.get("dynamics_id", -1)))
            logits = module.forward_inference(batch)[Columns.ACTION_DIST_INPUTS]
            action = torch.tanh(logits.chunk(2, dim=-1)[0])[0].cpu().numpy()
            state["last"] = action.astype(np.float32)
            return action

        return step


def rollout(
    module: Any,
    env_id: str,
    episodes: int,
    *,
    seed: int = 0,
    env_kwargs: Mapping[str, Any] | None = None,
    record_context: bool = False,
    reset_options: Mapping[str, Any] | None = None,
) -> Rollouts:
    """`episodes` deterministic episodes (reset seeds seed, seed + 1, ..., and
    `reset_options`), actions unsquashed onto the env's bounds."""
    actor = EscpActor(module, record_context)
    done = loop.rollout(
        actor, env_id, episodes, seed=seed, env_kwargs=env_kwargs, action_fn=loop.unsquash,
        reset_options=reset_options,
    )  # fmt: skip
    return Rollouts(
        returns=done.returns,
        lengths=done.lengths,
        episodes=done.episodes,
        contexts=[np.asarray(z) for z in actor.contexts],
        dynamics_ids=[np.asarray(i) for i in actor.dynamics_ids],
    )
