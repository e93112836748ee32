"""The online system identification network and its loss (torch only).

`VincentYu68/policy_transfer policy_transfer/uposi/train_osi.py`: `MLP(in_dim=H·obs_dim,
out_dim=len(dyn_params), layers=[256, 128, 64], activation=relu, last_activation=None)` over
the flattened history, fitted by squared error to the simulator's parameters
(`RegressorOptimizer.fit_data`). Here the history is ESCP's window of (s_t, a_{t−1}).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn


class OsiNetwork(nn.Module):
    """μ̂ = MLP(flatten(window)); `window` [B, H, step_dim] → [B, param_dim]."""

    def __init__(
        self,
        history_len: int,
        step_dim: int,
        param_dim: int,
        hidden: Sequence[int] = (256, 128, 64),
    ) -> None:
        super().__init__()
        self.history_len, self.step_dim = int(history_len), int(step_dim)
        layers: list[nn.Module] = []
        width = self.history_len * self.step_dim
        for h in hidden:
            layers += [nn.Linear(width, int(h)), nn.ReLU()]
            width = int(h)
        layers.append(nn.Linear(width, int(param_dim)))
        self.net = nn.Sequential(*layers)

    def forward(self, window: torch.Tensor) -> torch.Tensor:
        if window.dim() != 3 or tuple(window.shape[1:]) != (self.history_len, self.step_dim):
            raise ValueError(
                f"OsiNetwork expects a [B, {self.history_len}, {self.step_dim}] window, got "
                f"{tuple(window.shape)}"
            )
        return self.net(window.reshape(window.shape[0], -1))


def osi_loss(predicted: torch.Tensor, true: torch.Tensor) -> torch.Tensor:
    """Mean squared error of the estimate, averaged over rows and parameters."""
    return (predicted - true).pow(2).mean()
