"""Step 4: the GAN discriminator ω(s) = σ(f(s)), D_P labelled 1, D_Q labelled 0."""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import nn

from rllib_asor.asor.networks import mlp

LOG2 = math.log(2.0)


class Discriminator(nn.Module):
    """MLP that returns one logit per state (SRPO: 3×256 ReLU)."""

    def __init__(self, in_dim: int, hiddens: Sequence[int] = (256, 256, 256)) -> None:
        super().__init__()
        self.net = mlp(in_dim, hiddens, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Logits, shape [N]."""
        return self.net(x).squeeze(-1)


def discriminator_loss(
    logits: torch.Tensor, labels: torch.Tensor, label_smoothing: float = 0.0
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Class-balanced GAN loss ½(BCE_real + BCE_fake) and the statistics we log.

    `labels` is 1 for D_P, 0 for D_Q. With label smoothing ε the targets are 1−ε / ε. The
    statistics use unsmoothed targets: `js` = log 2 − ½(BCE_real + BCE_fake) is the
    discriminator's Jensen–Shannon estimate (0 = cannot tell the sets apart, log 2 = perfect).
    """
    labels = labels.float()
    real, fake = labels > 0.5, labels <= 0.5
    targets = labels * (1.0 - 2.0 * label_smoothing) + label_smoothing
    per_sample = F.binary_cross_entropy_with_logits(logits, targets, reduction="none")
    raw = F.binary_cross_entropy_with_logits(logits, labels, reduction="none")
    loss = 0.5 * (_masked_mean(per_sample, real) + _masked_mean(per_sample, fake))
    with torch.no_grad():
        bce_real, bce_fake = _masked_mean(raw, real), _masked_mean(raw, fake)
        p = torch.sigmoid(logits)
        entropy = -(p * torch.log(p.clamp_min(1e-8)) + (1 - p) * torch.log((1 - p).clamp_min(1e-8)))
        stats = {
            "disc_loss": loss.detach(),
            "disc_acc_real": _masked_mean((logits > 0).float(), real),
            "disc_acc_fake": _masked_mean((logits < 0).float(), fake),
            "disc_bce_real": bce_real,
            "disc_bce_fake": bce_fake,
            "disc_entropy": entropy.mean() if entropy.numel() else torch.zeros(()),
            "js_estimate": LOG2 - 0.5 * (bce_real + bce_fake),
        }
    return loss, stats


def _masked_mean(x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    n = mask.sum()
    return torch.where(n > 0, (x * mask).sum() / n.clamp_min(1), torch.zeros((), dtype=x.dtype))
