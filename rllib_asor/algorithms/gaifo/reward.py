"""GAIfO's features, reward and discriminator loss on tensors (torch only).

D(s, s′) = σ(logit(s, s′)), expert transitions labelled 1. The policy's reward is GAIL's
−log(1 − D(s, s′)) = softplus(logit) (`reward_form="gail"`, the form of `Ricky-Zhu/GARAT
rl_gat/reinforcedgat.py` `ATPEnv.step`, there with a 1e-8 inside the log) or AIRL's
log D − log(1 − D) = logit (`"airl"`). The loss is the class-balanced `discriminator_loss`
(½ of the mean BCE of expert rows and of policy rows, ASOR's form).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from rllib_asor.algorithms.gaifo.discriminator import discriminator_loss

FEATURES = ("s_next", "obs_next", "obs_delta")
"""The discriminator's inputs (`GaifoSettings.disc_input`)."""


def transition_features(
    obs: torch.Tensor,
    next_obs: torch.Tensor,
    state_dims: int | None = None,
    form: str = "s_next",
) -> torch.Tensor:
    """D's rows of transitions (o, o′), s the first `state_dims` (None: all) flattened features
    of o: `s_next` (s, s′), `obs_next` (o, s′), `obs_delta` (o, s′ − s)."""
    o, o2 = obs.reshape(obs.shape[0], -1), next_obs.reshape(next_obs.shape[0], -1)
    k = o.shape[1] if state_dims is None else state_dims
    if k > o.shape[1]:
        raise ValueError(
            f"gaifo.state_dims={state_dims} exceeds the observation's {o.shape[1]} features; "
            "allowed: at most that many"
        )
    s, s2 = o[:, :k], o2[:, :k]
    if form == "s_next":
        rows = [s, s2]
    elif form == "obs_next":
        rows = [o, s2]
    elif form == "obs_delta":
        rows = [o, s2 - s]
    else:
        raise ValueError(
            f"gaifo.disc_input={form!r} is not allowed; expected {' | '.join(FEATURES)}"
        )
    return torch.cat(rows, dim=-1).float()


def imitation_reward(logits: torch.Tensor, form: str = "gail") -> torch.Tensor:
    """The policy's reward from the discriminator's logits (expert = 1)."""
    if form == "gail":
        return F.softplus(logits)  # −log(1 − σ(x))
    if form == "airl":
        return logits  # log σ(x) − log(1 − σ(x))
    raise ValueError(f"gaifo.reward_form={form!r} is not allowed; expected gail | airl")


def gaifo_loss(
    expert_logits: torch.Tensor, policy_logits: torch.Tensor
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """½(BCE(expert, 1) + BCE(policy, 0)) and its statistics (`discriminator_loss`)."""
    return discriminator_loss(expert_logits, policy_logits)
