"""ASOR on MAPLE: partition real states, add the bonus to every row (real and model).

As the paper ("the procedure of MAPLE+ASOR is similar to ESCP+ASOR, where the datasets are
built with data from the offline dataset") and SRPO's MAPLE code
(`AIDefender/SRPO offlinerl/algo/modelbase/maple_st.py train_policy`) do it:

- the discriminator's batch is a separate batch of *real* dataset states (SRPO: 256 real
  segments' last states), ranked by V(s) = min(Q1, Q2)(s, π(s)) and, ASOR's addition, by the
  visitation proxy (`rllib_asor.asor.update.asor_update`: steps 1-6, λ and the statistics);
- the bonus λ·b(s) is then added to the reward of every step of the SAC batch, real and model
  segments alike (SRPO adds η·log(clamp(logit, 0.1, 10)) to every row's Q target), with b from
  the discriminator before this step's discriminator update.

Glue between MAPLE (`rllib_asor.algorithms.maple`, which knows nothing of ASOR) and the ASOR
core; `AsorMapleTorchLearner` (`rllib_asor.rllib.learners`) calls `maple_asor_bonus` in `_update`.
"""

from __future__ import annotations

import numpy as np
import torch

from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.proxy import ProxyInputs, VisitationProxy
from rllib_asor.asor.reward import potential_shaping, reward_bonus, standardize
from rllib_asor.asor.update import AsorBatch, AsorResult, AsorState, asor_update


def maple_asor_bonus(
    cfg: AsorConfig,
    state: AsorState,
    proxy: VisitationProxy | None,
    real: AsorBatch,
    obs: torch.Tensor,
    next_obs: torch.Tensor,
    terminateds: torch.Tensor,
    valid: torch.Tensor,
    rng: np.random.Generator,
) -> tuple[torch.Tensor, AsorResult]:
    """(λ·b for every row of `obs` `[..., D]` → `[...]`, the ASOR result on the real batch).

    `real` holds the real states with their values (and rewards, for λ's scale); `obs`,
    `next_obs`, `terminateds`, `valid` are the SAC batch's steps; padding (`valid` False) gets 0
    and stays out of the batch statistics."""
    result = asor_update(cfg, state, proxy, real, rng)
    lam = float(result.metrics.get("lambda", 0.0))
    lead = obs.shape[:-1]
    with torch.no_grad():
        flat, flat_next = obs.reshape(-1, obs.shape[-1]), next_obs.reshape(-1, obs.shape[-1])

        def raw(x: torch.Tensor) -> torch.Tensor:
            return reward_bonus(state.disc(x), cfg.reward_form, cfg.log_omega_min, cfg.logit_clip)

        mask = valid.reshape(-1).bool()
        b = raw(flat)
        if cfg.bonus_norm == "running":
            mean, var = state.bonus_rms.mean.reshape(()), state.bonus_rms.var.reshape(())
        elif cfg.bonus_norm == "batch":
            mean, var = b[mask].mean(), b[mask].var(unbiased=False)
        if cfg.bonus_norm != "off":
            b = standardize(b, mean, var, cfg.bonus_clip)
        if cfg.shaping == "potential":
            nb = raw(flat_next)
            if cfg.bonus_norm != "off":
                nb = standardize(nb, mean, var, cfg.bonus_clip)
            b = potential_shaping(b, nb, terminateds.reshape(-1), real.gamma)
        delta = (lam * b * mask).reshape(lead)
    if not torch.isfinite(delta).all():
        raise ValueError("ASOR on MAPLE: the reward bonus is NaN/inf")
    return delta, result


def real_batch(
    features: torch.Tensor,
    next_features: torch.Tensor,
    rewards: torch.Tensor,
    terminateds: torch.Tensor,
    values: torch.Tensor,
    gamma: float,
    timestep: float,
    actions: torch.Tensor | None = None,
    dynamics_ids: torch.Tensor | None = None,
) -> AsorBatch:
    """The `AsorBatch` of the real states that partition and train the discriminator
    (`actions` for the ensemble proxy, `dynamics_ids` for rnd_per_dynamics)."""
    return AsorBatch(
        features=features,
        env_rewards=rewards,
        values=values,
        gamma=gamma,
        timestep=timestep,
        proxy_inputs=ProxyInputs(features, actions, next_features, dynamics_ids),
        next_features=next_features,
        terminateds=terminateds,
    )
