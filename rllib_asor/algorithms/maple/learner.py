"""`MapleTorchLearner`: SAC on h-step segments with three optimizers, as the torch port.

`maple_st.py algo_init`: Adam for (policy GRU + actor), Adam for (value GRU + both critics) and
Adam for log α. The batch comes from `MAPLE.training_step` through `learner_group.update(
batch=...)` (no Learner connector): per segment row the columns of `segments.SEGMENT_KEYS`
and `HIDDEN_KEYS`, optionally `asor_bonus` (added to the rewards; the ASOR glue writes it).
Each optimizer gets the gradient of its own loss only (`torch.autograd.grad`), then the critics'
targets are Polyak-averaged (τ) after every step.
"""

from __future__ import annotations

from typing import Any

import torch
import torch.distributed as dist
from ray.rllib.core.learner.torch.torch_learner import TorchLearner

from rllib_asor.algorithms.common.learner_speed import SameMathSpeedMixin
from rllib_asor.algorithms.maple.losses import maple_losses
from rllib_asor.algorithms.maple.module import MapleTorchRLModule
from rllib_asor.algorithms.maple.segments import HIDDEN_KEYS, SEGMENT_KEYS

BONUS = "asor_bonus"
"""Optional `[B, T]` column added to the rewards before the TD target."""


class MapleTorchLearner(SameMathSpeedMixin, TorchLearner):
    """See the module docstring."""

    def configure_optimizers_for_module(self, module_id: str, config: Any = None) -> None:
        module = self.module[module_id].unwrapped()
        if not isinstance(module, MapleTorchRLModule):
            return super().configure_optimizers_for_module(module_id, config)
        s = module.settings
        nets = module.nets
        for name, params, lr in (
            ("actor", nets.actor_parameters(), s.actor_lr),
            ("critic", nets.critic_parameters(), s.critic_lr),
            ("alpha", [nets.log_alpha], s.alpha_lr),
        ):
            self.register_optimizer(
                module_id=module_id,
                optimizer_name=name,
                optimizer=torch.optim.Adam(params),
                params=params,
                lr_or_lr_schedule=lr,
            )

    def compute_loss_for_module(
        self, *, module_id: str, config: Any, batch: dict[str, Any], fwd_out: dict[str, Any]
    ) -> torch.Tensor:
        module = self.module[module_id].unwrapped()
        b = {k: batch[k] for k in (*SEGMENT_KEYS, *HIDDEN_KEYS)}
        b["valid"] = b["valid"].bool()
        b["terminateds"] = b["terminateds"].bool()
        lo, hi = (float(x) for x in module.reward_range)
        gamma = float(config.gamma)
        losses, stats = maple_losses(
            module.nets,
            b,
            gamma=gamma,
            target_entropy=-float(module.nets.action_dim),
            q_lo=lo / (1.0 - gamma),
            q_hi=hi / (1.0 - gamma),
            bonus=batch.get(BONUS),
        )
        if BONUS in batch:
            stats["asor_bonus_mean"] = float(
                (batch[BONUS] * b["valid"]).sum() / b["valid"].sum().clamp(min=1)
            )
        self._maple_losses[module_id] = losses
        self.metrics.log_dict(stats, key=module_id, window=1)
        return losses["critic"] + losses["actor"] + losses["alpha"]

    def _update(self, batch: dict[str, Any], **kwargs: Any) -> Any:
        self._maple_losses: dict[str, dict[str, torch.Tensor]] = {}
        return super()._update(batch, **kwargs)

    def compute_gradients(self, loss_per_module: dict[str, Any], **kwargs: Any) -> dict[Any, Any]:
        """Each optimizer's gradient of its own loss (`torch.autograd.grad`). That bypasses DDP's
        backward hooks, so with several Learners the gradients are averaged here, in the same
        (sorted) order on every rank."""
        grads: dict[Any, Any] = {}
        for module_id in sorted(loss_per_module):
            loss = loss_per_module[module_id]
            named = dict(self.get_optimizers_for_module(module_id))
            parts = self._maple_losses.get(module_id)
            module = self.module[module_id]
            by_ref = {self.get_param_ref(p): p for p in self.get_parameters(module)}
            for optim_name, optim in named.items():
                part = parts[optim_name] if parts is not None else loss
                own = self.filter_param_dict_for_optimizer(by_ref, optim)
                refs, params = list(own), list(own.values())
                gs = torch.autograd.grad(part, params, retain_graph=True, allow_unused=True)
                for ref, p, g in zip(refs, params, gs, strict=True):
                    grads[ref] = torch.zeros_like(p) if g is None else g
        if dist.is_available() and dist.is_initialized() and dist.get_world_size() > 1:
            for g in grads.values():  # dict order: the same on every rank
                dist.all_reduce(g)
                g /= dist.get_world_size()
        return grads

    def apply_gradients(self, gradients_dict: dict[Any, Any]) -> None:
        super().apply_gradients(gradients_dict)
        for module_id in self._maple_losses:
            module = self.module[module_id].unwrapped()
            module.nets.polyak(module.settings.tau)
