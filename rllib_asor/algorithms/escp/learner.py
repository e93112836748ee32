"""ESCP's Learner: SAC's update with z, and RMDM on the encoder (ESCP `algorithms/sac.py`,
`SAC.sac_update`), on the project's fast off-policy path (FastSACLearnerMixin: the batch is
built from the replay buffer's columns; several gradient steps per Learner call).

Per gradient step, as `SAC.sac_update` with `--rnn_fix_length 16 --stop_pg_for_ep`:
- critics: MSE to r + γ(1 − terminated)(min Q′(s′, a′, z̄) − α log π(a′ | s′, z′)), z̄ the
  task's moving average (before this step's RMDM), z′ the encoder on the target's window;
- actor: α log π(ã | s, z) − min Q(s, ã, z̄), z detached (no RL gradient into the encoder);
- temperature: −α·(log π + target entropy), α ≤ `max_alpha` (ESCP: log α clipped at 0),
  target entropy −1.5·|A| for `target_entropy="auto"`;
- encoder: `rmdm_scale` × RMDM (rmdm.py) once the switch-on rule holds, else no step; the
  moving averages move every step.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from ray.rllib.algorithms.sac.torch.sac_torch_learner import SACTorchLearner
from ray.rllib.core.columns import Columns
from ray.rllib.core.learner.learner import POLICY_LOSS_KEY
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.escp.module import CONTEXT, EscpTorchRLModule
from rllib_asor.algorithms.escp.replay import DYNAMICS_ID
from rllib_asor.algorithms.escp.rmdm import TaskSlots, rmdm_loss, rmdm_switched_on
from rllib_asor.algorithms.sac.learner import FastSACLearnerMixin

ENCODER_OPTIMIZER = "encoder"


class EscpLearnerMixin:
    """ESCP's losses and optimizers for `EscpTorchRLModule`s; other modules (ASOR's aux
    modules) go to the next class in the MRO. Mix in before `SACTorchLearner`."""

    def build(self) -> None:
        super().build()  # type: ignore[misc]
        self._escp_replay_size = 0
        for mid, module in self._escp_modules().items():
            ratio = module.escp.target_entropy_ratio
            target = self.config.get_config_for_module(mid).target_entropy  # type: ignore[attr-defined]
            if target is None or target == "auto":
                value = -ratio * float(np.prod(module.action_space.shape))
                entropy = torch.tensor(value, dtype=torch.float32, device=self.device)  # type: ignore[attr-defined]
                self.target_entropy[mid] = entropy  # type: ignore[attr-defined]

    def _escp_modules(self) -> dict[str, EscpTorchRLModule]:
        return {
            mid: m.unwrapped()
            for mid, m in self.module.items()  # type: ignore[attr-defined]
            if isinstance(m.unwrapped(), EscpTorchRLModule)
        }

    def configure_optimizers_for_module(self, module_id: str, config: Any = None) -> None:
        module = self.module[module_id].unwrapped()  # type: ignore[attr-defined]
        if not isinstance(module, EscpTorchRLModule):
            return super().configure_optimizers_for_module(module_id, config)  # type: ignore[misc]
        groups = {
            "qf": (list(module.qf.parameters()), config.critic_lr),
            "policy": (list(module.pi.parameters()), config.actor_lr),
            "alpha": ([self.curr_log_alpha[module_id]], config.alpha_lr),  # type: ignore[attr-defined]
            ENCODER_OPTIMIZER: (list(module.encoder.parameters()), module.escp.encoder_lr),
        }
        if module.twin_q:
            groups["qf_twin"] = (list(module.qf_twin.parameters()), config.critic_lr)
        for name, (params, lr) in groups.items():
            self.register_optimizer(  # type: ignore[attr-defined]
                module_id=module_id,
                optimizer_name=name,
                optimizer=torch.optim.Adam(params),
                params=params,
                lr_or_lr_schedule=lr,
            )

    def before_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        super().before_gradient_based_update(timesteps=timesteps)  # type: ignore[misc]
        self._escp_replay_size = int(timesteps.get(NUM_ENV_STEPS_SAMPLED_LIFETIME, 0) or 0)

    def compute_loss_for_module(
        self, *, module_id: str, config: Any, batch: dict[str, Any], fwd_out: dict[str, Any]
    ) -> torch.Tensor:
        module = self.module[module_id].unwrapped()  # type: ignore[attr-defined]
        if not isinstance(module, EscpTorchRLModule):
            return super().compute_loss_for_module(  # type: ignore[misc]
                module_id=module_id, config=config, batch=batch, fwd_out=fwd_out
            )
        log_alpha = self.curr_log_alpha[module_id]  # type: ignore[attr-defined]
        alpha = log_alpha.exp()
        not_done = 1.0 - batch[Columns.TERMINATEDS].float()
        v_next = fwd_out["q_target_next"] - alpha.detach() * fwd_out["logp_next_resampled"]
        target = (batch[Columns.REWARDS] + config.gamma * not_done * v_next).detach()
        qf_loss = (fwd_out["qf_preds"] - target).pow(2).mean()
        losses = {"qf": qf_loss}
        if module.twin_q:
            losses["qf_twin"] = (fwd_out["qf_twin_preds"] - target).pow(2).mean()
        logp = fwd_out["logp_resampled"]
        losses["policy"] = (alpha.detach() * logp - fwd_out["q_curr"]).mean()
        target_entropy = self.target_entropy[module_id]  # type: ignore[attr-defined]
        losses["alpha"] = -(alpha * (logp + target_entropy).detach()).mean()
        losses[ENCODER_OPTIMIZER] = self._rmdm(module_id, module, batch, fwd_out[CONTEXT])
        for name, loss in losses.items():
            compat.temp_losses(self)[(module_id, name + "_loss")] = loss
        self.metrics.log_dict(  # type: ignore[attr-defined]
            {
                POLICY_LOSS_KEY: losses["policy"],
                "qf_loss": qf_loss,
                "alpha_loss": losses["alpha"],
                "alpha_value": alpha[0],
                "logps": logp.mean(),
                "qf_mean": fwd_out["q_curr"].mean(),
            },
            key=module_id,
            window=1,
        )
        return (
            sum(v for k, v in losses.items() if k != ENCODER_OPTIMIZER) + losses[ENCODER_OPTIMIZER]
        )

    def _encoder_may_step(self, module: EscpTorchRLModule) -> bool:
        """False when RMDM cannot be on in this step whatever the batch (the replay is below
        `rmdm_min_replay`, or `rmdm_scale` is 0): z then needs no autograd graph."""
        s = module.escp
        return s.rmdm_scale != 0 and self._escp_replay_size >= s.rmdm_min_replay

    def _rmdm(
        self, module_id: str, module: EscpTorchRLModule, batch: dict[str, Any], z: torch.Tensor
    ) -> torch.Tensor:
        """The encoder's loss: RMDM when switched on, else a constant (no encoder step)."""
        s = module.escp
        slots = TaskSlots(module.task_ids).lookup(batch[DYNAMICS_ID].reshape(-1).long())
        res = rmdm_loss(
            z,
            slots,
            module.task_means,
            module.task_seen,
            tau=s.rmdm_tau,
            consistency_weight=s.consistency_weight,
            diversity_weight=s.diversity_weight,
            kernel=s.kernel,
            rbf_radius=s.rbf_radius,
        )
        num_tasks = s.num_tasks or int(module.task_seen.sum())
        on = res.loss is not None and rmdm_switched_on(
            self._escp_replay_size,
            res.num_tasks,
            num_tasks,
            s.rmdm_min_replay,
            s.rmdm_min_task_fraction,
        )
        stats = {
            "escp_batch_tasks": res.num_tasks,
            "escp_rmdm_on": float(on),
            "escp_z_abs_mean": z.detach().abs().mean(),
        }
        if res.loss is not None:
            stats.update(
                escp_rmdm_loss=res.loss.detach(),
                escp_consistency=res.consistency.detach(),
                escp_diversity=res.diversity.detach(),
            )
        self.metrics.log_dict(stats, key=module_id, window=1)  # type: ignore[attr-defined]
        if not on or s.rmdm_scale == 0:
            return torch.zeros((), device=z.device, requires_grad=True)  # encoder grads: None
        if not z.requires_grad:  # `_encoder_may_step` said no: it must agree with `on`
            raise RuntimeError("ESCP: RMDM switched on for a z computed without autograd")
        return res.loss * s.rmdm_scale

    def _update(self, batch: dict[str, Any], **kwargs: Any) -> Any:
        for module in self._escp_modules().values():
            module.encoder_grad = self._encoder_may_step(module)
        out = super()._update(batch, **kwargs)  # type: ignore[misc]
        with torch.no_grad():
            for mid, module in self._escp_modules().items():
                self.curr_log_alpha[mid].clamp_(max=math.log(module.escp.max_alpha))  # type: ignore[attr-defined]
        return out


class EscpTorchLearner(FastSACLearnerMixin, EscpLearnerMixin, SACTorchLearner):
    """ESCP's Learner (module docstring)."""
