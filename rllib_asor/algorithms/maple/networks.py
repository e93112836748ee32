"""MAPLE's networks: the GRU context extractor, the tanh-Gaussian actor and the twin critics.

Faithful to `AIDefender/SRPO` (= `polixir/OfflineRL`) `offlinerl/utils/net/model_GRU.py`
(`GRU_Model`), `offlinerl/utils/net/maple_actor.py` (`Maple_actor`) and
`offlinerl/utils/net/model/maple_critic.py` (`Maple_critic`):

- the GRU reads (s_t ⊕ a_{t−1}) → a 128-d hidden state; the policy and the critics each have
  their own GRU (`policy_gru`, `value_gru`);
- actor: Linear(128 → 16) (no activation: the 16-d context) ⊕ s → 256 → 256 (ReLU) → μ and
  log σ (clipped to [−20, 2]) → tanh-squashed Gaussian with the change-of-variables term;
- critic: Linear(128 → 16) ⊕ s ⊕ a → 256 → 256 (ReLU) → Q.

`context=False` (MOPO, the context switched off): no GRUs, actor on s and critics on (s, a).
"""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from rllib_asor.devices import module_device

LOG_STD_MIN, LOG_STD_MAX = -20.0, 2.0


def _mlp(in_dim: int, hiddens: tuple[int, ...], out_dim: int | None) -> nn.Sequential:
    layers: list[nn.Module] = []
    for h in hiddens:
        layers += [nn.Linear(in_dim, h), nn.ReLU()]
        in_dim = h
    if out_dim is not None:
        layers.append(nn.Linear(in_dim, out_dim))
    return nn.Sequential(*layers)


class ContextGRU(nn.Module):
    """GRU over (s_t ⊕ a_{t−1}) (`GRU_Model`): a batch of sequences, or one step."""

    def __init__(self, obs_dim: int, action_dim: int, hidden: int = 128) -> None:
        super().__init__()
        self.hidden = hidden
        self.gru = nn.GRU(obs_dim + action_dim, hidden, batch_first=True)

    def forward(
        self, obs: torch.Tensor, last_actions: torch.Tensor, h0: torch.Tensor
    ) -> torch.Tensor:
        """Hidden states after each step `[B, T, H]` from obs/last actions `[B, T, ·]`, h0 `[B, H]`.
        Steps after a sequence's end (padding) only change the outputs there (the GRU is
        causal), so no packing is needed where the losses mask them."""
        out, _ = self.gru(torch.cat([obs, last_actions], dim=-1), h0.unsqueeze(0).contiguous())
        return out

    def step(self, obs: torch.Tensor, last_actions: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
        """One step: `[N, ·]` inputs, `[N, H]` → `[N, H]`."""
        return self(obs.unsqueeze(1), last_actions.unsqueeze(1), h)[:, 0]


class MapleActor(nn.Module):
    """π(a | context, s), tanh-squashed Gaussian (`Maple_actor`)."""

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        gru_hidden: int = 128,
        context_dim: int = 16,
        hiddens: tuple[int, ...] = (256, 256),
    ) -> None:
        super().__init__()
        self.context = nn.Linear(gru_hidden, context_dim) if context_dim else None
        self.body = _mlp(context_dim + obs_dim, hiddens, None)
        self.mu = nn.Linear(hiddens[-1], action_dim)
        self.log_std = nn.Linear(hiddens[-1], action_dim)

    def dist_inputs(
        self, hidden: torch.Tensor | None, obs: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """(μ, log σ) before the squashing."""
        x = obs if self.context is None else torch.cat([self.context(hidden), obs], dim=-1)
        out = self.body(x)
        return self.mu(out), self.log_std(out).clamp(LOG_STD_MIN, LOG_STD_MAX)

    def forward(
        self, hidden: torch.Tensor | None, obs: torch.Tensor, deterministic: bool = False
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """(action in [−1, 1], log π(action)); reparameterised sample unless deterministic."""
        mu, log_std = self.dist_inputs(hidden, obs)
        return squashed_sample(mu, log_std, deterministic)


def squashed_sample(
    mu: torch.Tensor, log_std: torch.Tensor, deterministic: bool = False
) -> tuple[torch.Tensor, torch.Tensor]:
    """tanh(u), u ~ N(μ, σ) (or u = μ), and log π with the tanh correction
    (`Maple_actor.gaussian_likelihood`, `apply_squashing_func`)."""
    u = mu if deterministic else mu + log_std.exp() * torch.randn_like(mu)
    logp = (
        -0.5 * (((u - mu) / (log_std.exp() + 1e-8)) ** 2 + 2 * log_std + math.log(2 * np.pi))
    ).sum(-1)
    logp = logp - (2 * (math.log(2) - u - F.softplus(-2 * u))).sum(-1)
    return torch.tanh(u), logp


class MapleCritic(nn.Module):
    """Q(context, s, a) (`Maple_critic`)."""

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        gru_hidden: int = 128,
        context_dim: int = 16,
        hiddens: tuple[int, ...] = (256, 256),
    ) -> None:
        super().__init__()
        self.context = nn.Linear(gru_hidden, context_dim) if context_dim else None
        self.body = _mlp(context_dim + obs_dim + action_dim, hiddens, 1)

    def forward(
        self, hidden: torch.Tensor | None, obs: torch.Tensor, actions: torch.Tensor
    ) -> torch.Tensor:
        parts = [obs, actions] if self.context is None else [self.context(hidden), obs, actions]
        return self.body(torch.cat(parts, dim=-1)).squeeze(-1)


def segment_contexts(
    gru: ContextGRU,
    obs: torch.Tensor,
    last_actions: torch.Tensor,
    actions: torch.Tensor,
    next_obs: torch.Tensor,
    valid: torch.Tensor,
    h0: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor]:
    """GRU states for s_t and for s_{t+1} along h-step segments, each `[B, T, H]`.

    The state for s_{t+1} is the one for s_t's successor in the segment; for each segment's last
    valid step one more GRU step on (s′, a_t) (the port's `value_state_next`; it reads the
    padded output there, zero, for segments shorter than the batch)."""
    hid = gru(obs, last_actions, h0)
    b, t = valid.shape
    last = (valid.long().sum(1) - 1).clamp(min=0)
    rows = torch.arange(b, device=obs.device)
    extra = gru.step(next_obs[rows, last], actions[rows, last], hid[rows, last])
    nxt = torch.cat([hid[:, 1:], hid[:, -1:]], dim=1).clone()
    nxt[rows, last] = extra
    return hid, nxt


class MapleNetworks(nn.Module):
    """Everything MAPLE trains by SAC, as one module (`maple_st.py algo_init`): the policy GRU
    and actor, the value GRU and twin critics, their Polyak targets, and log α (init 0)."""

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        context: bool = True,
        gru_hidden: int = 128,
        context_dim: int = 16,
        hiddens: tuple[int, ...] = (256, 256),
    ) -> None:
        super().__init__()
        self.obs_dim, self.action_dim, self.use_context = obs_dim, action_dim, context
        self.gru_hidden = gru_hidden if context else 0
        ctx = context_dim if context else 0
        self.policy_gru = ContextGRU(obs_dim, action_dim, gru_hidden) if context else None
        self.value_gru = ContextGRU(obs_dim, action_dim, gru_hidden) if context else None
        self.actor = MapleActor(obs_dim, action_dim, gru_hidden, ctx, hiddens)
        self.q1 = MapleCritic(obs_dim, action_dim, gru_hidden, ctx, hiddens)
        self.q2 = MapleCritic(obs_dim, action_dim, gru_hidden, ctx, hiddens)
        self.target_q1 = MapleCritic(obs_dim, action_dim, gru_hidden, ctx, hiddens)
        self.target_q2 = MapleCritic(obs_dim, action_dim, gru_hidden, ctx, hiddens)
        self.target_q1.load_state_dict(self.q1.state_dict())
        self.target_q2.load_state_dict(self.q2.state_dict())
        for p in (*self.target_q1.parameters(), *self.target_q2.parameters()):
            p.requires_grad_(False)
        self.log_alpha = nn.Parameter(torch.zeros(1))

    def actor_parameters(self) -> list[nn.Parameter]:
        """The actor optimizer's parameters (policy GRU + actor)."""
        gru = list(self.policy_gru.parameters()) if self.policy_gru is not None else []
        return gru + list(self.actor.parameters())

    def critic_parameters(self) -> list[nn.Parameter]:
        """The critic optimizer's parameters (value GRU + both critics)."""
        gru = list(self.value_gru.parameters()) if self.value_gru is not None else []
        return gru + list(self.q1.parameters()) + list(self.q2.parameters())

    @torch.no_grad()
    def polyak(self, tau: float) -> None:
        """target ← (1 − τ)·target + τ·online (`_sync_weight`)."""
        for tgt, src in ((self.target_q1, self.q1), (self.target_q2, self.q2)):
            for pt, ps in zip(tgt.parameters(), src.parameters(), strict=True):
                pt.mul_(1.0 - tau).add_(ps, alpha=tau)

    @torch.no_grad()
    def policy_step(
        self,
        obs: torch.Tensor,
        last_actions: torch.Tensor,
        hidden: torch.Tensor,
        deterministic: bool = False,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """One acting step (`get_meta_action`): hidden ← GRU(hidden, s ⊕ a_{t−1}); a ~ π."""
        if self.policy_gru is not None:
            hidden = self.policy_gru.step(obs, last_actions, hidden)
            action, _ = self.actor(hidden, obs, deterministic)
        else:
            action, _ = self.actor(None, obs, deterministic)
        return action, hidden

    @torch.no_grad()
    def hidden_sequences(self, which: str, obs: np.ndarray, last_actions: np.ndarray) -> np.ndarray:
        """GRU outputs `[B, T, H]` along sequences from a zero state (`GRU_Model.get_hidden`);
        `which` = "policy" | "value"; `[B, T, 0]` without a context."""
        gru = self.policy_gru if which == "policy" else self.value_gru
        if gru is None:
            return np.zeros((*obs.shape[:2], 0), dtype=np.float32)
        device = module_device(gru)
        o, a = torch.as_tensor(obs, device=device), torch.as_tensor(last_actions, device=device)
        return gru(o, a, torch.zeros(o.shape[0], gru.hidden, device=device)).cpu().numpy()
