"""MAPLE's SAC losses on a batch of h-step segments, masked by validity.

Faithful to `AIDefender/SRPO offlinerl/algo/modelbase/maple_st.py AlgoTrainer.train_policy`:
contexts from each GRU along the segment (from the stored start hidden states); the TD target
y = r (+ ASOR/SRPO bonus) + γ·(1 − done)·(min target Q(s′, a′) − α·log π(a′|s′)), a′ ~ π,
clipped to [r_min/(1−γ), r_max/(1−γ)]; critic loss ½(Q1 + Q2 squared errors), actor loss
α·log π − min Q (critic context detached), α loss −log α·(log π + target entropy); every mean is
over the valid steps only (the port multiplies by the mask; here the MLPs run on the valid steps
alone, the same losses for fewer rows: model segments of poor data end early). The target critics read the online value GRU (no target GRU), as
the port.

One difference: RLlib computes every loss in one forward pass and steps the optimizers after,
so the actor loss reads the critics before this step's critic update (the port updates the
critics first). RLlib's own SAC does the same.
"""

from __future__ import annotations

from typing import Any

import torch

from rllib_asor.algorithms.maple.networks import MapleNetworks, segment_contexts


def contexts(nets: MapleNetworks, b: dict[str, torch.Tensor], which: str) -> tuple[Any, Any]:
    """(states for s_t, states for s_{t+1}) of the policy or value GRU; (None, None) without
    a context (MOPO)."""
    gru = nets.policy_gru if which == "policy" else nets.value_gru
    if gru is None:
        return None, None
    return segment_contexts(
        gru,
        b["obs"],
        b["last_actions"],
        b["actions"],
        b["next_obs"],
        b["valid"],
        b[f"{which}_hidden"],
    )


def maple_losses(
    nets: MapleNetworks,
    b: dict[str, torch.Tensor],
    *,
    gamma: float,
    target_entropy: float,
    q_lo: float,
    q_hi: float,
    bonus: torch.Tensor | None = None,
) -> tuple[dict[str, torch.Tensor], dict[str, float]]:
    """Losses {"critic", "actor", "alpha"} and statistics for one segment batch `b`
    (`obs`, `actions`, `next_obs`, `last_actions` `[B, T, ·]`; `rewards`, `terminateds`,
    `valid` `[B, T]`; `policy_hidden`, `value_hidden` `[B, H]`). `bonus` `[B, T]` is added to the
    rewards before the target (the port's `rew_reg_eta` term)."""
    mask = b["valid"].bool()
    v_hid, v_next = contexts(nets, b, "value")
    p_hid, p_next = contexts(nets, b, "policy")

    def rows(x: torch.Tensor | None) -> torch.Tensor | None:
        """The valid steps only, `[N, ·]`: the MLPs never see padding (same losses, fewer rows;
        the GRUs above ran over the whole segments)."""
        return None if x is None else x[mask]

    obs, actions, next_obs = rows(b["obs"]), rows(b["actions"]), rows(b["next_obs"])
    rewards = rows(b["rewards"] if bonus is None else b["rewards"] + bonus)
    terminateds = rows(b["terminateds"])
    v_hid, v_next, p_hid, p_next = rows(v_hid), rows(v_next), rows(p_hid), rows(p_next)
    q1 = nets.q1(v_hid, obs, actions)
    q2 = nets.q2(v_hid, obs, actions)
    alpha = nets.log_alpha.exp().detach()
    with torch.no_grad():
        a_next, logp_next = nets.actor(p_next, next_obs)
        v_next_d = None if v_next is None else v_next.detach()
        q_next = torch.min(
            nets.target_q1(v_next_d, next_obs, a_next),
            nets.target_q2(v_next_d, next_obs, a_next),
        )
        q_next = q_next - alpha * logp_next
        y = rewards + gamma * (1.0 - terminateds.float()) * q_next
        y = y.clamp(q_lo, q_hi)
    critic = 0.5 * (((q1 - y) ** 2).mean() + ((q2 - y) ** 2).mean())
    a_now, logp = nets.actor(p_hid, obs)
    alpha_loss = -(nets.log_alpha * (logp + target_entropy).detach()).mean()
    v_hid_d = None if v_hid is None else v_hid.detach()
    q_pi = torch.min(nets.q1(v_hid_d, obs, a_now), nets.q2(v_hid_d, obs, a_now))
    actor = (alpha * logp - q_pi).mean()
    with torch.no_grad():
        stats = {
            "critic_loss": float(critic),
            "actor_loss": float(actor),
            "alpha": float(alpha),
            "q_mean": float(q1.mean()),
            "target_mean": float(y.mean()),
            "entropy": float(-logp.mean()),
            "reward_mean": float(rewards.mean()),
            "valid_fraction": float(mask.float().mean()),
        }
    return {"critic": critic, "actor": actor, "alpha": alpha_loss}, stats


def state_values(
    nets: MapleNetworks,
    obs: torch.Tensor,
    last_actions: torch.Tensor,
    policy_hidden: torch.Tensor,
    value_hidden: torch.Tensor,
) -> torch.Tensor:
    """V(s) = min(Q1, Q2)(context, s, π(s)) with π's deterministic action, for single dataset
    states `[N, ·]` with the hidden states before them (ASOR's value ranking)."""
    with torch.no_grad():
        p = nets.policy_gru.step(obs, last_actions, policy_hidden) if nets.policy_gru else None
        v = nets.value_gru.step(obs, last_actions, value_hidden) if nets.value_gru else None
        action, _ = nets.actor(p, obs, deterministic=True)
        return torch.min(nets.q1(v, obs, action), nets.q2(v, obs, action))
