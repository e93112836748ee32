"""CaDM's context network, its context-conditioned forward and backward models, and its loss
(torch only).

`younggyoseo/CaDM cadm/dynamics/mlp_cadm_ensemble_cem_dynamics.py`:

- context c = MLP(history) with hidden layers 256-128-64 ReLU, output 10
  (`context_hidden_sizes`, `context_out_dim`);
- forward model on s ⊕ a ⊕ c: 4×200 swish, a Gaussian on Δs = s′ − s (`state_diff`) with log
  variance soft-bounded between learned limits (PETS); loss = mean((μ − Δs)²·e^(−logvar)) +
  mean(logvar) + 0.01·(Σ max_logvar − Σ min_logvar);
- backward model on s′ ⊕ a ⊕ c: 4×200 swish, its mean of s − s′ fitted by squared error,
  weighted by `back_coeff` (0.5).
Both models' gradients reach the context network: that is how the context is learnt.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import nn


def _mlp(inp: int, hidden: Sequence[int], out: int, act: type[nn.Module]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for h in hidden:
        layers += [nn.Linear(inp, int(h)), act()]
        inp = int(h)
    layers.append(nn.Linear(inp, out))
    return nn.Sequential(*layers)


class CadmModel(nn.Module):
    """The context network (called on a window: `model(window)` → c) and both dynamics
    models. `window` [B, H, obs_dim + act_dim] is ESCP's window of (s_t, a_{t−1})."""

    def __init__(
        self,
        obs_dim: int,
        act_dim: int,
        history_len: int,
        context_dim: int = 10,
        context_hidden: Sequence[int] = (256, 128, 64),
        model_hidden: Sequence[int] = (200, 200, 200, 200),
    ) -> None:
        super().__init__()
        self.obs_dim, self.act_dim, self.history_len = int(obs_dim), int(act_dim), int(history_len)
        step = self.obs_dim + self.act_dim
        self.context_net = _mlp(self.history_len * step, context_hidden, context_dim, nn.ReLU)
        inp = self.obs_dim + self.act_dim + int(context_dim)
        self.forward_model = _mlp(inp, model_hidden, 2 * self.obs_dim, nn.SiLU)
        self.backward_model = _mlp(inp, model_hidden, self.obs_dim, nn.SiLU)
        self.max_logvar = nn.Parameter(torch.full((self.obs_dim,), 0.5))
        self.min_logvar = nn.Parameter(torch.full((self.obs_dim,), -10.0))

    def forward(self, window: torch.Tensor) -> torch.Tensor:
        """The context c [B, context_dim] of `window` [B, H, obs_dim + act_dim]."""
        step = self.obs_dim + self.act_dim
        if window.dim() != 3 or tuple(window.shape[1:]) != (self.history_len, step):
            raise ValueError(
                f"CadmModel expects a [B, {self.history_len}, {step}] window, got "
                f"{tuple(window.shape)}"
            )
        return self.context_net(window.reshape(window.shape[0], -1))

    def predict_forward(
        self, obs: torch.Tensor, actions: torch.Tensor, context: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """(μ, log variance) of Δs = s′ − s, the log variance soft-bounded (PETS)."""
        mu, logvar = self.forward_model(torch.cat([obs, actions, context], -1)).chunk(2, -1)
        logvar = self.max_logvar - F.softplus(self.max_logvar - logvar)
        logvar = self.min_logvar + F.softplus(logvar - self.min_logvar)
        return mu, logvar

    def predict_backward(
        self, next_obs: torch.Tensor, actions: torch.Tensor, context: torch.Tensor
    ) -> torch.Tensor:
        """The mean of s − s′ from (s′, a, c)."""
        return self.backward_model(torch.cat([next_obs, actions, context], -1))


def cadm_loss(
    mu: torch.Tensor,
    logvar: torch.Tensor,
    delta: torch.Tensor,
    back_mu: torch.Tensor,
    back_delta: torch.Tensor,
    back_coeff: float = 0.5,
    max_logvar: torch.Tensor | None = None,
    min_logvar: torch.Tensor | None = None,
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """CaDM's loss: the forward Gaussian's mean((μ − Δs)²·e^(−logvar)) + mean(logvar), plus
    `back_coeff`·mean((μ_back − (s − s′))²), plus 0.01·(Σ max_logvar − Σ min_logvar) when the
    bounds are given; with its parts."""
    mu_loss = ((mu - delta).pow(2) * torch.exp(-logvar)).mean()
    var_loss = logvar.mean()
    back_loss = (back_mu - back_delta).pow(2).mean()
    loss = mu_loss + var_loss + back_coeff * back_loss
    if max_logvar is not None and min_logvar is not None:
        loss = loss + 0.01 * (max_logvar.sum() - min_logvar.sum())
    parts = {
        "cadm_forward_mse": (mu - delta).pow(2).mean().detach(),
        "cadm_backward_mse": back_loss.detach(),
        "cadm_loss": loss.detach(),
    }
    return loss, parts
