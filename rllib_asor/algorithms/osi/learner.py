"""UP-OSI's Learner: ESCP's SAC update (`EscpLearnerMixin`) with the true parameters as the
context, and OSI's regression in place of RMDM on the encoder's optimizer (Adam, `osi_lr`).

Per gradient step: critics, actor and temperature as ESCP's SAC (module.py feeds them μ);
OSI: `osi_weight` × mean squared error of μ̂(window) to the true μ, every step (the authors fit
OSI in rounds of 100 epochs on the data of their latest rollouts; here it trains on the replay
as SAC does)."""

from __future__ import annotations

from typing import Any

import torch
from ray.rllib.algorithms.sac.torch.sac_torch_learner import SACTorchLearner

from rllib_asor.algorithms.escp.learner import EscpLearnerMixin
from rllib_asor.algorithms.osi.module import OsiTorchRLModule
from rllib_asor.algorithms.osi.network import osi_loss
from rllib_asor.algorithms.osi.replay import PARAMS
from rllib_asor.algorithms.sac.learner import FastSACLearnerMixin


class OsiLearnerMixin(EscpLearnerMixin):
    """ESCP's losses with OSI's in place of RMDM for `OsiTorchRLModule`s."""

    def _encoder_may_step(self, module: Any) -> bool:
        return not isinstance(module, OsiTorchRLModule) or module.osi.osi_weight > 0

    def _rmdm(self, module_id: str, module: Any, batch: dict[str, Any], z: torch.Tensor) -> Any:
        if not isinstance(module, OsiTorchRLModule):
            return super()._rmdm(module_id, module, batch, z)
        mu = batch[PARAMS].float()
        loss = osi_loss(z, mu)
        with torch.no_grad():
            per_param = (z - mu).pow(2).mean(0)
            stats = {"osi_loss": loss.detach(), "osi_abs_error": (z - mu).abs().mean()}
            stats.update({f"osi_mse_{i}": v for i, v in enumerate(per_param)})
        self.metrics.log_dict(stats, key=module_id, window=1)  # type: ignore[attr-defined]
        if module.osi.osi_weight == 0:
            return torch.zeros((), device=z.device, requires_grad=True)
        return loss * module.osi.osi_weight


class OsiTorchLearner(FastSACLearnerMixin, OsiLearnerMixin, SACTorchLearner):
    """UP-OSI's Learner (module docstring)."""
