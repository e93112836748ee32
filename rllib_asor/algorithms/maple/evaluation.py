"""MAPLE's policy in the real env, stepping its GRU context (`maple_st.py test_one_trail`).

Deterministic actions (tanh of the mean), the hidden state and the last action carried from
step to step, zero at each reset (`maple_actor`, an actor of `rllib_asor.evaluation.rollout`);
D4RL-normalised with the dataset's own reference returns
(`rllib_asor.data.scoring.score_dynamics`), per dynamics and averaged over them, as the paper.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch

from rllib_asor.algorithms.maple.networks import MapleNetworks
from rllib_asor.data.scoring import score_dynamics
from rllib_asor.devices import module_device
from rllib_asor.evaluation.rollout import Actor, Step


def maple_actor(nets: MapleNetworks) -> Actor:
    """MAPLE's deterministic policy, a fresh zero hidden state and last action per episode."""
    device = module_device(nets)

    def episode() -> Step:
        state = {
            "hidden": torch.zeros(1, nets.gru_hidden, device=device),
            "last": torch.zeros(1, nets.action_dim, device=device),
        }

        @torch.no_grad()
        def step(obs: np.ndarray, info: Mapping[str, Any]) -> np.ndarray:
            o = torch.as_tensor(obs, dtype=torch.float32, device=device)[None]
            act, state["hidden"] = nets.policy_step(
                o, state["last"], state["hidden"], deterministic=True
            )
            state["last"] = act
            return act[0].cpu().numpy()

        return step

    return episode


def evaluate(
    nets: MapleNetworks,
    manifest: Mapping[str, Any],
    *,
    dynamics: Sequence[str] | None = None,
    episodes: int = 5,
    seed: int = 0,
) -> dict[str, dict[str, float]]:
    """Per dynamics `return_mean`, `return_std`, `normalized_score` (NaN where the dataset has
    no random/expert reference returns), plus their `mean` (`rllib_asor.data.scoring.evaluate`'s
    shape), the networks in eval mode meanwhile."""
    was_training = nets.training
    nets.eval()
    try:
        return score_dynamics(
            maple_actor(nets), manifest, dynamics=dynamics, episodes=episodes, seed=seed,
            unscored_ok=True,
        )  # fmt: skip
    finally:
        nets.train(was_training)
