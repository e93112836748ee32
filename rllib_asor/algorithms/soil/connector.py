"""SOIL's Learner connector piece (online): the policy's (s, a, s′) of each batch train the
inverse dynamics model, which then relabels the expert transitions; right after the batch became
tensors (`NumpyToTensor`, before GAE and before ASOR's piece when ASOR is on). It changes
nothing in the batch.

It sees PPO's batch as ASOR's piece does: torch tensors, each episode chunk ending with a
bootstrap row (`Columns.LOSS_MASK` False) that holds s_T, so the row after a valid row i is
s′ of row i.
"""

from __future__ import annotations

from typing import Any

import torch
from ray.rllib.connectors.connector_v2 import ConnectorV2
from ray.rllib.core.columns import Columns

from rllib_asor.algorithms.soil.imitation import SoilImitation

METRICS_KEY = "soil"
"""Where SOIL's statistics go in the Learner's results (`learners/soil/...`)."""


def valid_transitions(pb: dict[str, Any]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(s, a, s′) of the valid rows of one module's PPO batch (module docstring)."""
    mask = pb.get(Columns.LOSS_MASK)
    obs = pb[Columns.OBS]
    if mask is None or mask.dim() != 1:
        raise ValueError(
            "SOIL's piece needs PPO's flat batch with a loss mask (bootstrap rows); allowed: "
            "SOIL on PPO's default Learner connector pipeline, a module without state"
        )
    valid = mask.bool().nonzero().squeeze(-1)
    return obs[valid], pb[Columns.ACTIONS][valid], obs[valid + 1]


class SoilIdmPiece(ConnectorV2):
    """Trains the inverse dynamics model on the batch's transitions; relabels the experts."""

    def __init__(
        self,
        input_observation_space: Any = None,
        input_action_space: Any = None,
        *,
        imitation: SoilImitation,
        module_ids: tuple[str, ...],
        **kwargs: Any,
    ) -> None:
        super().__init__(input_observation_space, input_action_space, **kwargs)
        self.imitation = imitation
        self.module_ids = tuple(module_ids)

    def __call__(self, *, rl_module: Any, batch: dict, metrics: Any = None, **kwargs: Any) -> Any:
        parts = [valid_transitions(batch[mid]) for mid in self.module_ids if mid in batch]
        if parts:
            obs, act, nxt = (torch.cat(x) for x in zip(*parts, strict=True))
            stats = self.imitation.observe(obs, act, nxt)
            if metrics is not None and stats:
                metrics.log_dict(stats, key=METRICS_KEY, window=1)
        return batch
