"""SAC's Learner on the fast off-policy path: batches built straight from `FlatReplayBuffer`
rows, several gradient steps per Learner call, each followed by its Polyak target update
(rllib_asor/algorithms/sac/fast.py explains why)."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from ray.rllib.algorithms.sac.torch.sac_torch_learner import SACTorchLearner
from ray.rllib.core import ALL_MODULES
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.apis import TargetNetworkAPI
from ray.rllib.policy.sample_batch import MultiAgentBatch, SampleBatch

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.common.ddp import SortedModuleGradientsMixin
from rllib_asor.algorithms.common.learner_speed import SameMathSpeedMixin
from rllib_asor.algorithms.sac.replay import MINIBATCH_KEY, FlatTransitions


class FastSACLearnerMixin(SameMathSpeedMixin):
    """Builds the train batch straight from `FlatReplayBuffer` samples (`FlatTransitions`),
    skipping the learner connector's per-episode walk; other data goes the usual way.

    The batch has exactly the columns RLlib's SAC pipeline makes for n_step 1 (obs, new_obs,
    actions, rewards, terminateds, truncateds, n_step = 1, weights = 1), as torch tensors on
    the Learner's device. `_flat_batch_hook` lets ASOR rewrite it (rllib_asor/algorithms/sac/fast.py).
    """

    def _make_batch_if_necessary(self, training_data: Any) -> Any:
        episodes = training_data.episodes
        if not episodes or not all(isinstance(e, FlatTransitions) for e in episodes):
            return super()._make_batch_if_necessary(training_data)  # type: ignore[misc]
        policies = self.flat_batch_module_ids()
        if len(policies) != 1:
            raise ValueError(f"FlatReplayBuffer batches are single-agent; modules: {policies}")
        cols = episodes[0].columns
        if len(episodes) > 1:
            cols = {k: np.concatenate([e.columns[k] for e in episodes]) for k in cols}
        device = self.device  # type: ignore[attr-defined]
        n = len(cols[Columns.REWARDS])
        pb = {k: torch.from_numpy(np.ascontiguousarray(v)).to(device) for k, v in cols.items()}
        pb["n_step"] = torch.ones(n, dtype=torch.int64, device=device)
        pb["weights"] = torch.ones(n, dtype=torch.float32, device=device)
        batch = self._flat_batch_hook({policies[0]: pb})
        return MultiAgentBatch({mid: SampleBatch(b) for mid, b in batch.items()}, env_steps=n)

    def flat_batch_module_ids(self) -> list[str]:
        """The modules a flat batch trains (all; a subclass with extra modules narrows it)."""
        return list(self.module.keys())  # type: ignore[attr-defined]

    def _flat_batch_hook(self, batch: dict[str, Any]) -> dict[str, Any]:
        return batch

    def _create_iterator_if_necessary(self, *, training_data: Any, **kwargs: Any) -> Any:
        """Flat batches of several gradient steps: minibatches of the user's batch size."""
        episodes = training_data.episodes
        minibatch = (self.config.learner_config_dict or {}).get(MINIBATCH_KEY)  # type: ignore[attr-defined]
        self._fast_steps = bool(
            minibatch and episodes and all(isinstance(e, FlatTransitions) for e in episodes)
        )
        if self._fast_steps and not kwargs.get("minibatch_size"):
            kwargs["minibatch_size"] = int(minibatch)
            kwargs["num_epochs"] = 1
        return super()._create_iterator_if_necessary(training_data=training_data, **kwargs)  # type: ignore[misc]

    def _update(self, batch: dict[str, Any], **kwargs: Any) -> Any:
        out = super()._update(batch, **kwargs)  # type: ignore[misc]
        if getattr(self, "_fast_steps", False):
            self._polyak_targets()  # SAC's target update after every gradient step
        return out

    def after_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        if getattr(self, "_fast_steps", False):
            # Targets were updated after each minibatch; keep DQNLearner from doing it again.
            for mid in self.module.keys():  # type: ignore[attr-defined]
                self.last_update_ts_by_mid[mid] = float("inf")  # type: ignore[attr-defined]
            try:
                super().after_gradient_based_update(timesteps=timesteps)  # type: ignore[misc]
            finally:
                for mid in list(self.last_update_ts_by_mid):  # type: ignore[attr-defined]
                    self.last_update_ts_by_mid[mid] = 0  # type: ignore[attr-defined]
            return
        super().after_gradient_based_update(timesteps=timesteps)  # type: ignore[misc]

    def compute_gradients(self, loss_per_module: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        """One backward pass per module whose optimizers' losses touch disjoint parameters
        (`one_backward_module`), instead of RLlib's one per optimizer: the summed loss gives
        every parameter the gradient of its own optimizer's loss. Other modules, and every
        module with several Learners (DDP reduces per backward pass), go RLlib's way."""
        single = (self.config.num_learners or 0) <= 1  # type: ignore[attr-defined]
        ones = [m for m in loss_per_module if single and self.one_backward_module(m)]
        if not ones:
            return super().compute_gradients(loss_per_module, **kwargs)  # type: ignore[misc]
        temp = compat.temp_losses(self)
        grads: dict[Any, Any] = {}
        for module_id in sorted(ones):
            optims = [opt for _, opt in self.get_optimizers_for_module(module_id)]  # type: ignore[attr-defined]
            losses = [temp.pop(k) for k in [k for k in temp if k[0] == module_id]]
            for opt in optims:
                opt.zero_grad(set_to_none=True)
            torch.stack([loss.reshape(()) for loss in losses]).sum().backward()
            for opt in optims:
                for group in opt.param_groups:
                    grads.update({self.get_param_ref(p): p.grad for p in group["params"]})  # type: ignore[attr-defined]
        rest = {m: v for m, v in loss_per_module.items() if m not in ones}
        if any(m != ALL_MODULES for m in rest):
            grads.update(super().compute_gradients(rest, **kwargs))  # type: ignore[misc]
        return grads

    def one_backward_module(self, module_id: str) -> bool:
        """Whether `module_id`'s optimizer losses only reach their own parameters: its module
        says so (`disjoint_optimizer_losses`, e.g. the fast path's SAC module for Box actions:
        critic losses reach the critics only, targets detached; the policy loss π only, critics
        frozen, α detached; the α loss log α only, log π detached)."""
        module = self.module[module_id].unwrapped()  # type: ignore[attr-defined]
        return bool(getattr(module, "disjoint_optimizer_losses", False))

    @torch.no_grad()
    def _polyak_targets(self) -> None:
        for mid, module in self.module.items():  # type: ignore[attr-defined]
            inner = module.unwrapped()
            if not isinstance(inner, TargetNetworkAPI):
                continue
            tau = self.config.get_config_for_module(mid).tau  # type: ignore[attr-defined]
            main, target = [], []
            for main_net, target_net in inner.get_target_network_pairs():
                main.extend(main_net.parameters())
                target.extend(target_net.parameters())
            torch._foreach_lerp_(target, main, tau)


class FastSACTorchLearner(FastSACLearnerMixin, SortedModuleGradientsMixin, SACTorchLearner):
    """RLlib's SAC Learner that also reads `FlatReplayBuffer` batches (`fast_off_policy`)."""
