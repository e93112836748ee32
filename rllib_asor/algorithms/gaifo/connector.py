"""GAIfO's Learner connector piece: the discriminator's reward in place of the env's, then one
discriminator update, right after NumpyToTensor (before GAE and before ASOR's piece).

It sees PPO's batch as ASOR's piece does: torch tensors, each episode chunk ending with a
bootstrap row (`Columns.LOSS_MASK` False) that holds s_T, so the row after a valid row i is
s′ of row i. Rewards of valid rows become reward_scale·r_D(s, s′) + env_reward_weight·r_env,
with D as it was *before* this update's discriminator steps (the policy's transitions of this
batch then train D against the expert's).
"""

from __future__ import annotations

from typing import Any

import torch
from ray.rllib.connectors.connector_v2 import ConnectorV2
from ray.rllib.core.columns import Columns

from rllib_asor.algorithms.gaifo.trainer import GaifoTrainer

METRICS_KEY = "gaifo"
"""Where the discriminator's statistics go in the Learner's results (`learners/gaifo/...`)."""


class GaifoRewardPiece(ConnectorV2):
    """rewards ← D's reward (+ weighted env reward) of each valid row; then D's update (unless
    `disc_on_batch` is off)."""

    def __init__(
        self,
        input_observation_space: Any = None,
        input_action_space: Any = None,
        *,
        trainer: GaifoTrainer,
        module_ids: tuple[str, ...],
        **kwargs: Any,
    ) -> None:
        super().__init__(input_observation_space, input_action_space, **kwargs)
        self.trainer = trainer
        self.module_ids = tuple(module_ids)

    def __call__(self, *, rl_module: Any, batch: dict, metrics: Any = None, **kwargs: Any) -> Any:
        rows = [self._relabel(batch[mid]) for mid in self.module_ids if mid in batch]
        if not self.trainer.settings.disc_on_batch:
            return batch
        feats = torch.cat(rows) if rows else torch.zeros(0, self.trainer.expert.shape[1], device=self.trainer.device)
        stats = self.trainer.update(feats.to(self.trainer.device))
        if metrics is not None and stats:
            metrics.log_dict(stats, key=METRICS_KEY, window=1)
        return batch

    def _relabel(self, pb: dict[str, Any]) -> torch.Tensor:
        """Writes the new rewards into `pb`; returns the (s, s′) features of its valid rows."""
        rewards, mask = pb[Columns.REWARDS], pb.get(Columns.LOSS_MASK)
        if mask is None or rewards.dim() != 1:
            raise ValueError(
                "GAIfO's reward piece needs PPO's flat batch with a loss mask (bootstrap rows); "
                "allowed: GAIfO on PPO's default Learner connector pipeline"
            )
        obs = pb[Columns.OBS]
        valid = mask.bool().nonzero().squeeze(-1)
        feats = self.trainer.features(obs[valid], obs[valid + 1])
        s = self.trainer.settings
        new = self.trainer.reward(feats).to(rewards.dtype).to(rewards.device)
        if s.env_reward_weight:
            new = new + s.env_reward_weight * rewards[valid]
        out = rewards.clone()
        out[valid] = new
        pb[Columns.REWARDS] = out
        return feats
