"""Step 5: the reward bonus from ω(s), its normalisation and shaping, and λ (constant,
schedule, or dual ascent)."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from rllib_asor.asor.config import REWARD_FORMS, LambdaSpec
from rllib_asor.asor.networks import RunningMeanStd


def reward_bonus(
    logits: torch.Tensor,
    form: str = "log",
    log_omega_min: float = -5.0,
    logit_clip: float = 5.0,
) -> torch.Tensor:
    """Per-state bonus b(s); the reward becomes r + λ·b(s). Always finite.

    - `log`: log ω = logsigmoid(logit), clipped below at `log_omega_min` (paper; b ≤ 0).
    - `centered`: the clipped log ω minus its batch mean (zero-mean bonus).
    - `gail`: −log(1 − ω) = −logsigmoid(−logit), clipped above at −log_omega_min (b ≥ 0).
    - `logit`: the logit log ω − log(1 − ω) clipped to ±`logit_clip` (AIRL/DAC: zero at
      ω = ½, two-signed, bounded).
    """
    if form not in REWARD_FORMS:
        raise ValueError(
            f"asor.reward_form={form!r} is invalid: allowed {' | '.join(REWARD_FORMS)}"
        )
    if not torch.isfinite(logits).all():
        raise ValueError("ASOR: the discriminator produced NaN/inf logits")
    if form == "gail":
        return (-F.logsigmoid(-logits)).clamp(max=-log_omega_min)
    if form == "logit":
        return logits.clamp(-logit_clip, logit_clip)
    log_omega = F.logsigmoid(logits).clamp(min=log_omega_min)
    if form == "centered" and log_omega.numel() > 0:
        return log_omega - log_omega.mean()
    return log_omega


def scheduled_lambda(spec: LambdaSpec, timestep: float) -> float:
    """λ at `timestep` for a constant or a piecewise-linear `[[t, v], ...]` schedule.

    Before the first point the first value holds, after the last point the last value.
    """
    if isinstance(spec, str):
        raise ValueError('scheduled_lambda: "auto" has no schedule; use dual_ascent_step')
    if isinstance(spec, int | float):
        return float(spec)
    ts = [p[0] for p in spec]
    vs = [p[1] for p in spec]
    if timestep <= ts[0]:
        return float(vs[0])
    for (t0, v0), (t1, v1) in zip(spec, spec[1:], strict=False):
        if timestep <= t1:
            return float(v0 + (v1 - v0) * (timestep - t0) / (t1 - t0))
    return float(vs[-1])


def dual_ascent_step(
    lam: float, js_estimate: float, target: float, lr: float, lam_max: float
) -> float:
    """λ ← clip(λ + η·(d̂ − ε), 0, λ_max): raise λ while the JS divergence exceeds ε."""
    return float(min(max(lam + lr * (js_estimate - target), 0.0), lam_max))


def standardize(
    bonus: torch.Tensor, mean: torch.Tensor, var: torch.Tensor, clip: float
) -> torch.Tensor:
    """(b − mean) / √(var + 1e-8), clipped to ±clip."""
    return ((bonus - mean) / torch.sqrt(var + 1e-8)).clamp(-clip, clip)


@torch.no_grad()
def reward_scale(rms: RunningMeanStd) -> float:
    """The env reward's running RMS, √(var + mean²): 1 for a constant reward of 1, 0 only for
    an env that has paid nothing yet (then the relative bonus is 0, never NaN)."""
    return float(torch.sqrt(rms.var + rms.mean.pow(2)).reshape(-1)[0])


def potential_shaping(
    bonus: torch.Tensor, next_bonus: torch.Tensor, terminateds: torch.Tensor, gamma: float
) -> torch.Tensor:
    """F = γ·b(s′) − b(s), with b(s′) = 0 after termination (Ng, Harada & Russell 1999)."""
    return gamma * next_bonus * (~terminateds.bool()).to(bonus.dtype) - bonus


def explained_variance(values: torch.Tensor, targets: torch.Tensor) -> float:
    """1 − Var(targets − values) / Var(targets); −1 when the targets are constant."""
    if targets.numel() > 1:
        var = targets.var(unbiased=False)
    else:
        var = torch.zeros((), dtype=targets.dtype, device=targets.device)
    if var <= 1e-12:
        return -1.0
    return float(1.0 - (targets - values).var(unbiased=False) / var)
