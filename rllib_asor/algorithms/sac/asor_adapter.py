"""SAC's answers to the ASOR piece (and those of SAC's kin: ESCP, OSI): V(s) = min(Q1, Q2)(s, π(s))
ranks the replayed states, or the module's own `state_values(batch)` where it has one (ESCP's
and OSI's, with their contexts); every row is ranked, and λ·b(s) goes into the rewards before the TD target (the piece sits at
the end of the Learner connector; on the fast path the Learner applies it to the batch it
builds from the flat buffer's rows)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import torch
from ray.rllib.core.columns import Columns
from ray.rllib.core.models.base import ENCODER_OUT

from rllib_asor.algorithms.common.asor_adapter import AsorAdapter
from rllib_asor.evaluation.rollout import deterministic_sample


def soft_q_state_values(module: Any, batch: dict[str, Any]) -> torch.Tensor:
    """V(s) for SAC/CQL modules: min over the twin critics of Q(s, π(s)).

    Continuous actions: π's deterministic action, the squashed mean; discrete: the expectation
    under π.
    """
    obs = {Columns.OBS: batch[Columns.OBS]}
    logits = module.pi(module.pi_encoder(obs)[ENCODER_OUT])
    if isinstance(module.action_space, gym.spaces.Discrete):
        q_all = module.compute_q_values(obs, squeeze=False)
        return (torch.softmax(logits, dim=-1) * q_all).sum(-1)
    action = deterministic_sample(module.get_train_action_dist_cls().from_logits(logits))
    return module.compute_q_values({**obs, Columns.ACTIONS: action})


class SACAsorAdapter(AsorAdapter):
    """SAC: soft-Q state values, the bonus on every replayed row's reward."""

    def state_values(self, module: Any, batch: dict[str, Any]) -> torch.Tensor:
        own = getattr(module, "state_values", None)  # ESCP's, OSI's: V(s) with their context
        return own(batch) if callable(own) else soft_q_state_values(module, batch)
