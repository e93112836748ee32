"""Small torch building blocks shared by the discriminator, RND and the dynamics ensemble."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn


def mlp(in_dim: int, hiddens: Sequence[int], out_dim: int) -> nn.Sequential:
    """ReLU MLP in_dim → hiddens → out_dim (no output activation)."""
    layers: list[nn.Module] = []
    for h in hiddens:
        layers += [nn.Linear(in_dim, h), nn.ReLU()]
        in_dim = h
    layers.append(nn.Linear(in_dim, out_dim))
    return nn.Sequential(*layers)


class RunningMeanStd(nn.Module):
    """Running mean/variance (Chan et al. parallel update) kept as buffers.

    Buffers travel with `state_dict`, so the statistics survive checkpoint/restore. They are
    float32 because RLlib's checkpoints store module state as float32 (float64 would come back
    rounded); the update itself runs in float64.
    """

    def __init__(self, shape: int | Sequence[int], epsilon: float = 1e-4) -> None:
        super().__init__()
        shape = (shape,) if isinstance(shape, int) else tuple(shape)
        self.register_buffer("mean", torch.zeros(shape))
        self.register_buffer("var", torch.ones(shape))
        self.register_buffer("count", torch.tensor(float(epsilon)))

    @torch.no_grad()
    def update(self, x: torch.Tensor) -> None:
        """Fold a batch [N, *shape] into the statistics."""
        if x.shape[0] == 0:
            return
        x = x.detach().to(torch.float64)
        mean, var, count = self.mean.double(), self.var.double(), self.count.double()
        b_mean, b_var, b_n = x.mean(0), x.var(0, unbiased=False), x.shape[0]
        delta, total = b_mean - mean, count + b_n
        m2 = var * count + b_var * b_n + delta.pow(2) * count * b_n / total
        self.mean.copy_(mean + delta * b_n / total)
        self.var.copy_(m2 / total)
        self.count.copy_(total)

    def normalize(self, x: torch.Tensor, clip: float = 5.0) -> torch.Tensor:
        """(x − mean) / std, clipped to ±clip, in x's dtype."""
        std = torch.sqrt(self.var + 1e-8)
        return ((x - self.mean.to(x.dtype)) / std.to(x.dtype)).clamp(-clip, clip)
