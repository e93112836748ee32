"""RLlib 2.60's PPO loss without host syncs (the same formulas, the same metrics).

`PPOTorchLearner.compute_loss_for_module` averages over the valid rows with `x[mask]`: a
boolean-mask gather whose output size only the host can know, so on a GPU each of its six
masked means (and the two in the backward pass) waits for the stream to drain, and
`explained_variance` copies a host tensor to the device: ~9 stalls per minibatch. Here the
masked mean is `sum(where(mask, x, 0)) / num_valid` (the same value; rows outside the mask
get zero gradient, as with the gather) and the explained variance is clamped at -1 on the
device. Only the order of the floating-point additions changes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch
from ray.rllib.algorithms.ppo.ppo import (
    LEARNER_RESULTS_KL_KEY,
    LEARNER_RESULTS_VF_EXPLAINED_VAR_KEY,
    LEARNER_RESULTS_VF_LOSS_UNCLIPPED_KEY,
)
from ray.rllib.core.columns import Columns
from ray.rllib.core.learner.learner import ENTROPY_KEY, POLICY_LOSS_KEY, VF_LOSS_KEY
from ray.rllib.evaluation.postprocessing import Postprocessing
from ray.rllib.utils.numpy import SMALL_NUMBER


def masked_mean(mask: torch.Tensor | None) -> Callable[[torch.Tensor], torch.Tensor]:
    """The mean over the rows where `mask` is True (all rows without a mask), sync-free."""
    if mask is None:
        return torch.mean
    num_valid = torch.sum(mask)

    def mean(x: torch.Tensor) -> torch.Tensor:
        return torch.sum(torch.where(mask, x, 0.0)) / num_valid

    return mean


def explained_variance(y: torch.Tensor, pred: torch.Tensor) -> torch.Tensor:
    """`ray.rllib.utils.torch_utils.explained_variance` (max(-1, 1 - var(y - pred) / var(y)))
    without its host-to-device copy of -1."""
    y = y.squeeze()
    y_var = torch.var(y, dim=0)
    diff_var = torch.var(y - pred.squeeze(), dim=0)
    return torch.clamp(1 - diff_var / (y_var + SMALL_NUMBER), min=-1.0)


class SyncFreePPOLossMixin:
    """`compute_loss_for_module` of RLlib 2.60's `PPOTorchLearner`, line for line, with the
    sync-free masked mean and explained variance above. Mix in before PPO's Learner."""

    def compute_loss_for_module(
        self, *, module_id: str, config: Any, batch: dict[str, Any], fwd_out: dict[str, Any]
    ) -> torch.Tensor:
        module = self.module[module_id].unwrapped()  # type: ignore[attr-defined]
        mean = masked_mean(batch.get(Columns.LOSS_MASK))

        curr_dist = module.get_train_action_dist_cls().from_logits(
            fwd_out[Columns.ACTION_DIST_INPUTS]
        )
        prev_dist = module.get_exploration_action_dist_cls().from_logits(
            batch[Columns.ACTION_DIST_INPUTS]
        )
        logp_ratio = torch.exp(curr_dist.logp(batch[Columns.ACTIONS]) - batch[Columns.ACTION_LOGP])

        if config.use_kl_loss:
            mean_kl_loss = mean(prev_dist.kl(curr_dist))
        else:
            mean_kl_loss = logp_ratio.new_zeros(())

        curr_entropy = curr_dist.entropy()
        mean_entropy = mean(curr_entropy)

        advantages = batch[Postprocessing.ADVANTAGES]
        surrogate_loss = torch.min(
            advantages * logp_ratio,
            advantages * torch.clamp(logp_ratio, 1 - config.clip_param, 1 + config.clip_param),
        )

        if config.use_critic:
            value_fn_out = module.compute_values(batch, embeddings=fwd_out.get(Columns.EMBEDDINGS))
            vf_loss = torch.pow(value_fn_out - batch[Postprocessing.VALUE_TARGETS], 2.0)
            vf_loss_clipped = torch.clamp(vf_loss, 0, config.vf_clip_param)
            mean_vf_loss = mean(vf_loss_clipped)
            mean_vf_unclipped_loss = mean(vf_loss)
        else:
            z = surrogate_loss.new_zeros(())
            value_fn_out = mean_vf_unclipped_loss = vf_loss_clipped = mean_vf_loss = z

        entropy_coeff = self.entropy_coeff_schedulers_per_module[module_id].get_current_value()  # type: ignore[attr-defined]
        total_loss = mean(
            -surrogate_loss + config.vf_loss_coeff * vf_loss_clipped - entropy_coeff * curr_entropy
        )
        if config.use_kl_loss:
            total_loss += self.curr_kl_coeffs_per_module[module_id] * mean_kl_loss  # type: ignore[attr-defined]

        self.metrics.log_dict(  # type: ignore[attr-defined]
            {
                POLICY_LOSS_KEY: -mean(surrogate_loss),
                VF_LOSS_KEY: mean_vf_loss,
                LEARNER_RESULTS_VF_LOSS_UNCLIPPED_KEY: mean_vf_unclipped_loss,
                LEARNER_RESULTS_VF_EXPLAINED_VAR_KEY: explained_variance(
                    batch[Postprocessing.VALUE_TARGETS], value_fn_out
                ),
                ENTROPY_KEY: mean_entropy,
                LEARNER_RESULTS_KL_KEY: mean_kl_loss,
            },
            key=module_id,
            window=1,
        )
        return total_loss
