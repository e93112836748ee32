"""Model rollouts of h steps from dataset states, with MOPO's uncertainty penalty.

Faithful to `AIDefender/SRPO offlinerl/algo/modelbase/maple_st.py` (`AlgoTrainer.rollout_model`
and the clip ranges set in `AlgoTrainer.train`):

- starts: dataset steps drawn uniformly (`SimpleReplayTrajPool.random_batch_for_initial`), each
  with its last action and the policy's and critics' GRU hidden states before that step;
- one elite member per trajectory, drawn at the first step and kept (`model_indexes`);
  s′, r ~ N(μ_k, σ_k) of that member;
- penalty u = min(max_k ‖σ_k(s, a)‖, clip) over the elites (`uncertainty_mode='aleatoric'`;
  σ over next state and reward); reward r − λ·u;
- terminated by the env's rule on the sampled s′ (before clipping); s′ then clipped to the
  data's range widened by 5 % of it on each side, and at least to ±`clip_floor` (the port's
  `np.maximum(obs_max, 100)`; 0 switches the floor off); r clipped to
  [min r − λ·clip, max r] of the data;
- after a termination the trajectory's later steps are invalid (`valid` False); the port keeps
  stepping them, here they are not computed (zeros: nothing reads invalid steps).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from rllib_asor.algorithms.maple.ensemble import GaussianEnsemble
from rllib_asor.algorithms.maple.termination import TerminationFn
from rllib_asor.devices import module_device

PolicyStep = Callable[[torch.Tensor, torch.Tensor, torch.Tensor], tuple[torch.Tensor, torch.Tensor]]
"""(s_t, a_{t−1}, hidden before t) → (a_t sampled, hidden after t)."""


@dataclass(frozen=True)
class ClipRange:
    """Where model states and rewards are kept."""

    obs_lo: np.ndarray
    obs_hi: np.ndarray
    rew_lo: float
    rew_hi: float


def clip_range(
    obs: np.ndarray,
    rewards: np.ndarray,
    penalty_coef: float,
    penalty_clip: float,
    expand: float = 0.05,
    floor: float = 100.0,
) -> ClipRange:
    """The port's ranges: states in [min − 5 %, max + 5 %] of the data (at least ±floor);
    rewards in [min r − λ·clip, max r]."""
    lo, hi = obs.min(0).astype(np.float64), obs.max(0).astype(np.float64)
    pad = (hi - lo) * expand
    lo, hi = lo - pad, hi + pad
    if floor > 0:
        lo, hi = np.minimum(lo, -floor), np.maximum(hi, floor)
    return ClipRange(
        obs_lo=lo.astype(np.float32),
        obs_hi=hi.astype(np.float32),
        rew_lo=float(rewards.min() - penalty_clip * penalty_coef),
        rew_hi=float(rewards.max()),
    )


def uncertainty(logstd: torch.Tensor) -> torch.Tensor:
    """max over members of ‖σ_k‖ (MOPO's aleatoric penalty); logstd `[K, N, D]` → `[N]`."""
    return logstd.exp().norm(dim=-1).max(dim=0).values


def penalized_reward(
    reward: torch.Tensor, logstd: torch.Tensor, coef: float, clip: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """(r − λ·min(u, clip), u clipped), both `[N]`."""
    u = uncertainty(logstd).clamp(max=clip)
    return reward - coef * u, u


@dataclass
class RolloutStats:
    """Per-rollout summary (logged under `maple/`)."""

    uncertainty_mean: float
    uncertainty_max: float
    valid_fraction: float
    terminated_fraction: float
    reward_mean: float


@torch.no_grad()
def model_rollout(
    ensemble: GaussianEnsemble,
    policy_step: PolicyStep,
    starts: dict[str, np.ndarray],
    horizon: int,
    terminated_fn: TerminationFn,
    limits: ClipRange,
    penalty_coef: float,
    penalty_clip: float,
    rng: np.random.Generator,
    chunk: int = 10_000,
) -> tuple[dict[str, np.ndarray], RolloutStats]:
    """Segments of `horizon` model steps from `starts` (keys `obs`, `last_actions`,
    `policy_hidden`, `value_hidden`, each `[N, ·]`), as the module doc says.

    Returns `obs`, `actions`, `next_obs`, `last_actions` `[N, h, ·]`; `rewards` (penalised),
    `terminateds`, `valid` `[N, h]`; the start hidden states `[N, H]`; and the statistics."""
    n = len(starts["obs"])
    parts = [
        _rollout_chunk(
            ensemble,
            policy_step,
            {k: v[i : i + chunk] for k, v in starts.items()},
            horizon,
            terminated_fn,
            limits,
            penalty_coef,
            penalty_clip,
            rng,
        )
        for i in range(0, n, chunk)
    ]
    out = {k: np.concatenate([p[0][k] for p in parts]) for k in parts[0][0]}
    us = np.concatenate([p[1] for p in parts])
    valid = out["valid"]
    stats = RolloutStats(
        uncertainty_mean=float(us.mean()) if us.size else 0.0,
        uncertainty_max=float(us.max()) if us.size else 0.0,
        valid_fraction=float(valid.mean()) if valid.size else 0.0,
        terminated_fraction=float((out["terminateds"] & valid).any(1).mean()) if n else 0.0,
        reward_mean=float(out["rewards"][valid].mean()) if valid.any() else 0.0,
    )
    return out, stats


def _rollout_chunk(
    ensemble: GaussianEnsemble,
    policy_step: PolicyStep,
    starts: dict[str, np.ndarray],
    horizon: int,
    terminated_fn: TerminationFn,
    limits: ClipRange,
    penalty_coef: float,
    penalty_clip: float,
    rng: np.random.Generator,
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    n, device = len(starts["obs"]), module_device(ensemble)

    def on_device(x: np.ndarray, dtype: torch.dtype | None = None) -> torch.Tensor:
        return torch.as_tensor(x, dtype=dtype, device=device)

    f32 = torch.float32
    obs = on_device(starts["obs"], f32).clone()  # stepped in place
    last = on_device(starts["last_actions"], f32).clone()
    hidden = on_device(starts["policy_hidden"], f32).clone()
    lo, hi = on_device(limits.obs_lo, f32), on_device(limits.obs_hi, f32)
    member = on_device(rng.integers(0, len(ensemble.elite_idx), size=n))
    alive = np.ones(n, dtype=bool)
    act_dim = last.shape[1]
    keys = ("obs", "actions", "next_obs", "last_actions", "rewards", "terminateds", "valid")
    steps: dict[str, list[np.ndarray]] = {k: [] for k in keys}
    us = []
    for _ in range(horizon):
        # Only the trajectories still alive are stepped (the port steps them all and masks the
        # rest as invalid; what invalid steps hold is never read): rows after a termination
        # stay zero.
        idx = np.flatnonzero(alive)
        t_idx = on_device(idx)
        step = {
            "obs": np.zeros((n, obs.shape[1]), np.float32),
            "actions": np.zeros((n, act_dim), np.float32),
            "next_obs": np.zeros((n, obs.shape[1]), np.float32),
            "last_actions": np.zeros((n, act_dim), np.float32),
            "rewards": np.zeros(n, np.float32),
            "terminateds": np.zeros(n, bool),
            "valid": alive.copy(),
        }
        if len(idx):
            o, a_prev = obs[t_idx], last[t_idx]
            act, h_new = policy_step(o, a_prev, hidden[t_idx])
            mu, logstd = ensemble.elites(o, act)
            noise = on_device(rng.standard_normal(mu.shape[1:]), f32)
            rows, m = torch.arange(len(idx), device=device), member[t_idx]
            sample = mu[m, rows] + logstd[m, rows].exp() * noise
            next_obs, reward = sample[:, :-1], sample[:, -1]
            term = terminated_fn(next_obs.cpu().numpy())
            next_obs = torch.maximum(torch.minimum(next_obs, hi), lo)
            reward = reward.clamp(limits.rew_lo, limits.rew_hi)
            reward, u = penalized_reward(reward, logstd, penalty_coef, penalty_clip)
            us.append(u.cpu().numpy())
            for k, v in (
                ("obs", o),
                ("actions", act),
                ("next_obs", next_obs),
                ("last_actions", a_prev),
                ("rewards", reward),
            ):
                step[k][idx] = v.cpu().numpy()
            step["terminateds"][idx] = term
            obs[t_idx], last[t_idx], hidden[t_idx] = next_obs, act, h_new
            alive[idx[term]] = False
        for k in keys:
            steps[k].append(step[k])
    out = {k: np.stack(v, axis=1) for k, v in steps.items()}
    out["policy_hidden"] = np.asarray(starts["policy_hidden"], dtype=np.float32)
    out["value_hidden"] = np.asarray(starts["value_hidden"], dtype=np.float32)
    return out, np.concatenate(us) if us else np.zeros(0, np.float32)
