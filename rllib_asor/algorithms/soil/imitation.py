"""SOIL's demonstration term, owned by the Learner: the expert transitions, the inverse dynamics
model that labels them, and the weight w_k = λ0·λ1^k of training iteration k.

`observe(obs, actions, next_obs)` adds the policy's transitions to the model's buffer, trains it
(`idm_steps` minibatches) and relabels every expert transition (SOIL's `train_from_paths`);
`loss(module, n)` is w_k · (N_demo / N_batch) · the mean −log π(â | s) of `n` random expert
rows: SOIL's DAPG gradient, which sums the expert rows' terms (advantage w_k each) with the
sampled rows' and divides by the number of sampled rows, in the minibatch form of PPO's loss.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch
from ray.rllib.core.columns import Columns

from rllib_asor.algorithms.common.demonstrations import Demonstrations
from rllib_asor.algorithms.common.inverse_dynamics import IdmTrainer, imitation_loss
from rllib_asor.algorithms.soil.settings import SoilSettings


class SoilImitation:
    """The expert rows, their inferred actions and the inverse dynamics model (module doc)."""

    def __init__(
        self,
        settings: SoilSettings,
        demos: Demonstrations,
        action_space: gym.Space,
        batch_size: int,
        device: Any = "cpu",
        rank: int = 0,
    ) -> None:
        self.settings = settings
        self.device = torch.device(device)
        obs_dim = int(np.prod(demos.obs_shape))
        self.idm = IdmTrainer(
            obs_dim,
            action_space,
            hiddens=settings.idm_hiddens,
            lr=settings.idm_lr,
            steps=settings.idm_steps,
            batch_size=settings.idm_batch_size,
            capacity=settings.idm_capacity,
            seed=settings.seed,
            device=self.device,
        )
        self.obs = torch.as_tensor(demos.obs, device=self.device)
        self.next_obs = torch.as_tensor(demos.next_obs, device=self.device)
        self.labels: torch.Tensor | None = None
        self.batch_size = int(batch_size)
        self.iteration = 0
        self._rng = np.random.default_rng(settings.seed + 1000 * rank)

    def weight(self) -> float:
        """w_k · N_demo / N_batch of the current iteration k (0, 1, ...)."""
        s = self.settings
        return s.demo_weight * s.demo_decay**self.iteration * len(self.obs) / self.batch_size

    def observe(self, obs: Any, actions: Any, next_obs: Any, steps: int | None = None) -> dict:
        """Add the policy's transitions, train the model, relabel the expert rows."""
        self.idm.add(obs, actions, next_obs)
        stats = self.idm.update(steps)
        self.labels = self.idm.infer(self.obs, self.next_obs)
        return stats

    def loss(self, module: Any, n: int) -> tuple[torch.Tensor, dict[str, float]]:
        """The demonstration term on `n` random expert rows, and its statistics."""
        if self.labels is None or n < 1 or self.weight() == 0.0:
            return torch.zeros((), device=self.device), {}
        idx = torch.as_tensor(self._rng.integers(0, len(self.obs), n), device=self.device)
        out = module.forward_train({Columns.OBS: self.obs[idx]})
        dist = module.get_train_action_dist_cls().from_logits(out[Columns.ACTION_DIST_INPUTS])
        logp = dist.logp(self.labels[idx])
        w = self.weight()
        return imitation_loss(logp, w), {"demo_logp": float(logp.mean().detach()), "demo_w": w}

    def get_state(self) -> dict[str, Any]:
        return {
            "idm": self.idm.get_state(),
            "iteration": self.iteration,
            "labels": None if self.labels is None else self.labels.cpu(),
            "rng": self._rng.bit_generator.state,
        }

    def set_state(self, state: dict[str, Any]) -> None:
        self.idm.set_state(state["idm"])
        self.iteration = int(state["iteration"])
        labels = state.get("labels")
        self.labels = None if labels is None else labels.to(self.device)
        self._rng.bit_generator.state = state["rng"]
