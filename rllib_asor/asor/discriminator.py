"""Step 4: the GAN discriminator ω(s) = σ(f(s)), D_P labelled 1, D_Q labelled 0."""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import nn

from rllib_asor.asor.networks import RunningMeanStd, mlp

LOG2 = math.log(2.0)


class Discriminator(nn.Module):
    """MLP that returns one logit per state (SRPO: 3×256 ReLU), optionally on inputs
    normalised by a running mean/std (updated with `observe`, clipped to ±5)."""

    def __init__(
        self, in_dim: int, hiddens: Sequence[int] = (256, 256, 256), input_norm: bool = False
    ) -> None:
        super().__init__()
        self.net = mlp(in_dim, hiddens, 1)
        self.input_rms = RunningMeanStd(in_dim) if input_norm else None

    def normalize(self, x: torch.Tensor) -> torch.Tensor:
        """The network's input for raw features x."""
        return x if self.input_rms is None else self.input_rms.normalize(x)

    @torch.no_grad()
    def observe(self, x: torch.Tensor) -> None:
        """Fold raw features into the input normaliser (no-op without one)."""
        if self.input_rms is not None:
            self.input_rms.update(x)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Logits, shape [N]."""
        return self.net(self.normalize(x)).squeeze(-1)

    def regularizer(
        self, real: torch.Tensor, grad_penalty: float, logit_reg: float
    ) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """grad_penalty·E‖∇ logit(s)‖² on real samples (w.r.t. the normalised input; AMP/ASE)
        plus logit_reg·‖W_out‖² (ASE's logit regularisation)."""
        gp = torch.zeros((), device=real.device)
        if grad_penalty > 0 and real.shape[0] > 0:
            z = self.normalize(real).detach().requires_grad_(True)
            gp = _input_grad_norm(self.net(z).sum(), z)
        return self._regularised(gp, grad_penalty, logit_reg)

    def training_loss(
        self,
        x: torch.Tensor,
        labels: torch.Tensor,
        label_smoothing: float,
        grad_penalty: float,
        logit_reg: float,
    ) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """`discriminator_loss` plus `regularizer` on raw features x in one forward pass: the
        gradient penalty is taken on that pass's real rows (each row's logit depends on its own
        input only, so it is the penalty a second pass over them gives)."""
        real = labels > 0.5
        z = self.normalize(x).detach()
        penalise = grad_penalty > 0 and bool(real.any())
        if penalise:
            z.requires_grad_(True)
        logits = self.net(z).squeeze(-1)
        loss, stats = discriminator_loss(logits, labels, label_smoothing)
        gp = torch.zeros((), device=x.device)
        if penalise:
            gp = _input_grad_norm(logits[real].sum(), z, rows=real)
        reg, reg_stats = self._regularised(gp, grad_penalty, logit_reg)
        return loss + reg, {**stats, **reg_stats}

    def _regularised(
        self, gp: torch.Tensor, grad_penalty: float, logit_reg: float
    ) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        out_w = self.net[-1].weight
        lr = out_w.pow(2).sum() if logit_reg > 0 else torch.zeros((), device=out_w.device)
        loss = grad_penalty * gp + logit_reg * lr
        return loss, {"disc_grad_penalty": gp.detach(), "disc_logit_norm": out_w.detach().norm()}


def _input_grad_norm(
    out: torch.Tensor, z: torch.Tensor, rows: torch.Tensor | None = None
) -> torch.Tensor:
    """E‖∂out/∂z‖² over z's rows (or the `rows` mask of them), differentiable."""
    (grad,) = torch.autograd.grad(out, z, create_graph=True)
    if rows is not None:
        grad = grad[rows]
    return grad.pow(2).sum(-1).mean()


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
            "disc_entropy": (
                entropy.mean() if entropy.numel() else torch.zeros((), device=logits.device)
            ),
            "js_estimate": LOG2 - 0.5 * (bce_real + bce_fake),
        }
    return loss, stats


def _masked_mean(x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    n = mask.sum()
    zero = torch.zeros((), dtype=x.dtype, device=x.device)
    return torch.where(n > 0, (x * mask).sum() / n.clamp_min(1), zero)
