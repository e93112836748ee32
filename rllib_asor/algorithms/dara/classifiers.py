"""DARC's domain classifiers and DARA's reward correction Δr (torch only).

Follows `google-research/google-research darc/classifiers.py build_classifier`: an (s, a)
classifier and a residual (s, a, s′) classifier whose logits are added to the (s, a) logits
(`sas_logits = sa_logits + advantage_logits`), one hidden ReLU layer of 32 each, two logits
(0 = source, 1 = target), Gaussian input noise σ = 1 in training only; and `darc_agent.py`:
the loss is the sum of the two cross-entropies on a batch half source, half target, and
Δr = log p_sas(1) − log p_sas(0) − log p_sa(1) + log p_sa(0), read without noise.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import nn

SOURCE, TARGET = 0, 1
"""Class indices of the classifiers' two logits."""


def _mlp(inp: int, hidden: Sequence[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for h in hidden:
        layers += [nn.Linear(inp, h), nn.ReLU()]
        inp = h
    layers.append(nn.Linear(inp, 2))
    return nn.Sequential(*layers)


class DomainClassifiers(nn.Module):
    """q(domain | s, a) and q(domain | s, a, s′) as DARC builds them (module docstring)."""

    def __init__(
        self, obs_dim: int, action_dim: int, hidden: Sequence[int] = (32,), input_noise: float = 1.0
    ) -> None:
        super().__init__()
        self.obs_dim, self.action_dim = int(obs_dim), int(action_dim)
        self.input_noise = float(input_noise)
        self.sa = _mlp(obs_dim + action_dim, hidden)
        self.advantage = _mlp(2 * obs_dim + action_dim, hidden)

    def logits(
        self, obs: torch.Tensor, actions: torch.Tensor, next_obs: torch.Tensor, noisy: bool = False
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """(sa_logits, sas_logits), each `[N, 2]`; `noisy` adds DARC's input noise."""
        sas = torch.cat([obs, actions, next_obs], dim=-1)
        sa = sas[..., : self.obs_dim + self.action_dim]
        if noisy and self.input_noise > 0:
            sas = sas + self.input_noise * torch.randn_like(sas)
            sa = sa + self.input_noise * torch.randn_like(sa)
        sa_logits = self.sa(sa)
        return sa_logits, sa_logits + self.advantage(sas)


def classifier_loss(
    model: DomainClassifiers,
    source: tuple[torch.Tensor, torch.Tensor, torch.Tensor],
    target: tuple[torch.Tensor, torch.Tensor, torch.Tensor],
    noisy: bool = True,
) -> tuple[torch.Tensor, dict[str, float]]:
    """Mean cross-entropy of both classifiers (summed, as DARC) on source rows (label 0) and
    target rows (label 1), each given as (s, a, s′); with statistics."""
    obs, actions, next_obs = (torch.cat([x, y]) for x, y in zip(source, target, strict=True))
    labels = torch.cat(
        [
            torch.full((len(source[0]),), SOURCE, dtype=torch.long, device=obs.device),
            torch.full((len(target[0]),), TARGET, dtype=torch.long, device=obs.device),
        ]
    )
    sa_logits, sas_logits = model.logits(obs, actions, next_obs, noisy=noisy)
    sa_loss = F.cross_entropy(sa_logits, labels)
    sas_loss = F.cross_entropy(sas_logits, labels)
    with torch.no_grad():
        stats = {
            "sa_loss": float(sa_loss),
            "sas_loss": float(sas_loss),
            "sa_accuracy": float((sa_logits.argmax(-1) == labels).float().mean()),
            "sas_accuracy": float((sas_logits.argmax(-1) == labels).float().mean()),
        }
    return sa_loss + sas_loss, stats


def delta_reward(
    model: DomainClassifiers,
    obs: torch.Tensor,
    actions: torch.Tensor,
    next_obs: torch.Tensor,
    clip: float = 10.0,
) -> torch.Tensor:
    """Δr `[N]` = log p(t|s,a,s′)/p(s|s,a,s′) − log p(t|s,a)/p(s|s,a), no input noise,
    clipped to ±`clip`: about log T_target(s′|s,a) − log T_source(s′|s,a), negative where a
    source transition is unlikely under the target's dynamics."""
    with torch.no_grad():
        sa_logits, sas_logits = model.logits(obs, actions, next_obs, noisy=False)
        sas = F.log_softmax(sas_logits, dim=-1)
        sa = F.log_softmax(sa_logits, dim=-1)
        delta = sas[:, TARGET] - sas[:, SOURCE] - sa[:, TARGET] + sa[:, SOURCE]
        return delta.clamp(-clip, clip)
