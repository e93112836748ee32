"""GAIfO's discriminator D(s, s′) = σ(logit) and its loss (torch only).

The same network and loss form as ASOR's (`rllib_asor.asor.discriminator`: an MLP with one
logit, class-balanced BCE, the Jensen–Shannon estimate), kept here because `algorithms/` does not
import ASOR's code (tests/test_import_graph.py). Inputs are normalised by fixed statistics (the
expert rows', set once), clipped to ±5.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import nn

from rllib_asor.algorithms.gaifo.settings import GRAD_PENALTY_FORMS

LOG2 = math.log(2.0)


class TransitionDiscriminator(nn.Module):
    """MLP (ReLU) → one logit per row, on inputs normalised by `fit_normalizer`'s statistics."""

    def __init__(self, in_dim: int, hiddens: Sequence[int] = (64, 64)) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        width = int(in_dim)
        for h in hiddens:
            layers += [nn.Linear(width, int(h)), nn.ReLU()]
            width = int(h)
        layers.append(nn.Linear(width, 1))
        self.net = nn.Sequential(*layers)
        self.register_buffer("mean", torch.zeros(in_dim))
        self.register_buffer("std", torch.ones(in_dim))

    @torch.no_grad()
    def fit_normalizer(self, x: torch.Tensor) -> None:
        """Normalise inputs by the mean and std of the rows `x` from now on."""
        self.mean.copy_(x.mean(0))
        self.std.copy_(x.std(0, unbiased=False).clamp_min(1e-4))

    def normalize(self, x: torch.Tensor) -> torch.Tensor:
        return ((x - self.mean) / self.std).clamp(-5.0, 5.0)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Logits, shape [N]."""
        return self.net(self.normalize(x)).squeeze(-1)

    def gradient_penalty(
        self, real: torch.Tensor, fake: torch.Tensor | None = None, form: str = "zero_centred"
    ) -> torch.Tensor:
        """The gradient penalty of `form` (`GRAD_PENALTY_FORMS`), w.r.t. the normalised input:
        `zero_centred` E‖∇ logit‖² at the `real` rows; `one_centred_mix` E(‖∇ logit‖ − 1)² at
        mixtures α·real + (1 − α)·fake of the normalised rows, paired in order (the first
        min(len) of each), α ~ N(0, 1) per element (the GARAT authors' `compute_grad_pen`,
        `rl_gat/gat.py`; the mixtures are not clipped)."""
        if form == "zero_centred":
            return self._grad(self.normalize(real)).pow(2).sum(-1).mean()
        if form != "one_centred_mix":
            raise ValueError(bad_form(form))
        n = 0 if fake is None else min(real.shape[0], fake.shape[0])
        if n == 0:
            return torch.zeros((), device=real.device)
        z_real, z_fake = self.normalize(real[:n]), self.normalize(fake[:n])
        alpha = torch.randn_like(z_real)
        grad = self._grad(alpha * z_real + (1 - alpha) * z_fake)
        return (grad.norm(2, dim=-1) - 1).pow(2).mean()

    def _grad(self, z: torch.Tensor) -> torch.Tensor:
        """∇_z logit per row of normalised inputs `z` (differentiable in the weights)."""
        z = z.detach().requires_grad_(True)
        (grad,) = torch.autograd.grad(self.net(z).sum(), z, create_graph=True)
        return grad


def bad_form(form: str) -> str:
    """The one-line error for an unknown gradient penalty form."""
    return f"grad_penalty_form={form!r}; allowed: {' | '.join(GRAD_PENALTY_FORMS)}"


def discriminator_loss(
    expert_logits: torch.Tensor, policy_logits: torch.Tensor
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """½ mean BCE(expert, 1) + ½ mean BCE(policy, 0) and its statistics; `js_estimate` =
    log 2 − the loss (0: D cannot tell the two apart, log 2: perfectly)."""
    bce_real = F.binary_cross_entropy_with_logits(expert_logits, torch.ones_like(expert_logits))
    bce_fake = F.binary_cross_entropy_with_logits(policy_logits, torch.zeros_like(policy_logits))
    loss = 0.5 * (bce_real + bce_fake)
    with torch.no_grad():
        stats = {
            "disc_loss": loss.detach(),
            "disc_acc_real": (expert_logits > 0).float().mean(),
            "disc_acc_fake": (policy_logits < 0).float().mean(),
            "disc_bce_real": bce_real.detach(),
            "disc_bce_fake": bce_fake.detach(),
            "js_estimate": LOG2 - loss.detach(),
        }
    return loss, stats
