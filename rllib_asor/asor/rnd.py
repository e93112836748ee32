"""Random Network Distillation as a visitation-count proxy: c(s) = −‖f̂(s) − f(s)‖²."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from rllib_asor.asor.networks import RunningMeanStd, mlp


class RND(nn.Module):
    """Frozen random target f, trained predictor f̂, running input normalisation (clip ±5).

    The target's parameters have `requires_grad=False`; optimisers must skip them.
    """

    def __init__(
        self,
        in_dim: int,
        hiddens: Sequence[int] = (128, 128),
        embedding_dim: int = 64,
        seed: int | None = None,
    ) -> None:
        super().__init__()
        gen_state = torch.random.get_rng_state()
        if seed is not None:
            torch.manual_seed(seed)
        self.target = mlp(in_dim, hiddens, embedding_dim)
        self.predictor = mlp(in_dim, hiddens, embedding_dim)
        if seed is not None:
            torch.random.set_rng_state(gen_state)
        for p in self.target.parameters():
            p.requires_grad_(False)
        self.obs_rms = RunningMeanStd(in_dim)

    def prediction_error(self, x: torch.Tensor) -> torch.Tensor:
        """Per-sample mean squared error between predictor and target, shape [N]."""
        z = self.obs_rms.normalize(x)
        with torch.no_grad():
            target = self.target(z)
        return (self.predictor(z) - target).pow(2).mean(-1)

    @torch.no_grad()
    def count_proxy(self, x: torch.Tensor) -> torch.Tensor:
        """Higher = visited more: −prediction error, shape [N]."""
        return -self.prediction_error(x)

    def update_normalizer(self, x: torch.Tensor) -> None:
        """Fold a batch of raw inputs into the running mean/std."""
        self.obs_rms.update(x)
