"""PPO's answers to the ASOR piece: V(s) from PPO's critic ranks the states, every valid row
(loss mask) is ranked, and the reward is rewritten before GAE, which reuses the same V(s)."""

from __future__ import annotations

from typing import Any

import torch
from ray.rllib.connectors.learner import GeneralAdvantageEstimation

from rllib_asor.algorithms.common.asor_adapter import AsorAdapter


class PPOAsorAdapter(AsorAdapter):
    """PPO (and any `ValueFunctionAPI` module with GAE: APPO, IMPALA)."""

    insert_before = GeneralAdvantageEstimation
    shares_values_with_gae = True

    def state_values(self, module: Any, batch: dict[str, Any]) -> torch.Tensor:
        return module.compute_values(batch)
