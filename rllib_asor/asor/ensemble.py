"""Ensemble disagreement as a visitation-count proxy: c(s, a) = −max_k ‖μ_k − mean_k μ‖.

K dynamics models predict the normalised change s_{t+1} − s_t from (s_t, a_t). Where they
agree the region has been seen often; disagreement is high on rarely visited states.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from rllib_asor.asor.networks import RunningMeanStd, mlp


class DynamicsEnsemble(nn.Module):
    """K independent MLP dynamics models with shared input/target normalisers."""

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        size: int = 5,
        hiddens: Sequence[int] = (128, 128),
    ) -> None:
        super().__init__()
        self.models = nn.ModuleList(
            mlp(obs_dim + action_dim, hiddens, obs_dim) for _ in range(size)
        )
        self.obs_rms = RunningMeanStd(obs_dim)
        self.delta_rms = RunningMeanStd(obs_dim)

    def predictions(self, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Normalised predicted deltas, shape [K, N, obs_dim]."""
        x = torch.cat([self.obs_rms.normalize(obs), actions.float()], dim=-1)
        return torch.stack([m(x) for m in self.models])

    def loss(
        self, obs: torch.Tensor, actions: torch.Tensor, next_obs: torch.Tensor
    ) -> torch.Tensor:
        """Sum over models of the MSE to the normalised true delta."""
        target = self.delta_rms.normalize(next_obs - obs)
        return (self.predictions(obs, actions) - target.unsqueeze(0)).pow(2).mean(dim=(1, 2)).sum()

    @torch.no_grad()
    def disagreement(self, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """u = max_k ‖μ_k − mean_k μ‖, shape [N]."""
        preds = self.predictions(obs, actions)
        return (preds - preds.mean(0, keepdim=True)).norm(dim=-1).max(0).values

    @torch.no_grad()
    def count_proxy(self, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Higher = visited more: −disagreement, shape [N]."""
        return -self.disagreement(obs, actions)

    def update_normalizers(self, obs: torch.Tensor, next_obs: torch.Tensor) -> None:
        """Fold a batch of transitions into the input and target statistics."""
        self.obs_rms.update(obs)
        self.delta_rms.update(next_obs - obs)
