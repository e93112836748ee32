"""BCO's Learner: behavioural cloning, −mean log π(â | s), on expert states and the actions the
inverse dynamics model inferred for them (the batches `BCO.training_step` builds)."""

from __future__ import annotations

from typing import Any

from ray.rllib.core.columns import Columns
from ray.rllib.core.learner.torch.torch_learner import TorchLearner

from rllib_asor.algorithms.common.inverse_dynamics import imitation_loss


class BcoTorchLearner(TorchLearner):
    """A torch Learner whose loss is behavioural cloning's (module docstring)."""

    def compute_loss_for_module(
        self, *, module_id: str, config: Any, batch: dict[str, Any], fwd_out: dict[str, Any]
    ) -> Any:
        module = self.module[module_id].unwrapped()
        dist = module.get_train_action_dist_cls().from_logits(fwd_out[Columns.ACTION_DIST_INPUTS])
        logp = dist.logp(batch[Columns.ACTIONS])
        loss = imitation_loss(logp)
        self.metrics.log_value((module_id, "bc_loss"), loss.detach(), window=1)
        return loss
