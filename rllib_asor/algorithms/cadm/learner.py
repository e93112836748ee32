"""CaDM's Learner: ESCP's SAC update (`EscpLearnerMixin`) with CaDM's context, and CaDM's
prediction loss in place of RMDM on the encoder's optimizer (Adam, `model_lr`): every gradient
step, the forward model predicts Δs = s′ − s and the backward model s − s′ of the batch's
transitions from the window's context, whose gradient trains the context network."""

from __future__ import annotations

from typing import Any

import torch
from ray.rllib.algorithms.sac.torch.sac_torch_learner import SACTorchLearner
from ray.rllib.core.columns import Columns

from rllib_asor.algorithms.cadm.model import cadm_loss
from rllib_asor.algorithms.cadm.module import CadmTorchRLModule
from rllib_asor.algorithms.escp.learner import EscpLearnerMixin
from rllib_asor.algorithms.sac.learner import FastSACLearnerMixin


class CadmLearnerMixin(EscpLearnerMixin):
    """ESCP's losses with CaDM's in place of RMDM for `CadmTorchRLModule`s."""

    def _encoder_may_step(self, module: Any) -> bool:
        return not isinstance(module, CadmTorchRLModule) or module.cadm.model_weight > 0

    def _rmdm(self, module_id: str, module: Any, batch: dict[str, Any], z: torch.Tensor) -> Any:
        if not isinstance(module, CadmTorchRLModule):
            return super()._rmdm(module_id, module, batch, z)
        model = module.encoder
        obs, actions = batch[Columns.OBS].float(), batch[Columns.ACTIONS].float()
        next_obs = batch[Columns.NEXT_OBS].float()
        mu, logvar = model.predict_forward(obs, actions, z)
        back_mu = model.predict_backward(next_obs, actions, z)
        loss, parts = cadm_loss(
            mu,
            logvar,
            next_obs - obs,
            back_mu,
            obs - next_obs,
            module.cadm.back_coeff,
            model.max_logvar,
            model.min_logvar,
        )
        self.metrics.log_dict(parts, key=module_id, window=1)  # type: ignore[attr-defined]
        if module.cadm.model_weight == 0:
            return torch.zeros((), device=z.device, requires_grad=True)
        return loss * module.cadm.model_weight


class CadmTorchLearner(FastSACLearnerMixin, CadmLearnerMixin, SACTorchLearner):
    """CaDM's Learner (module docstring)."""
