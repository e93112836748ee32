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
from ray.rllib.core.columns import Columns

from rllib_asor.algorithms.maple.learner import BONUS, MapleTorchLearner
from rllib_asor.algorithms.maple.losses import state_values
from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.proxy import ProxyInputs, VisitationProxy
from rllib_asor.asor.update import (
    AsorBatch,
    AsorResult,
    AsorState,
    asor_update,
    bonus_for_rows,
    concat_batches,
)
from rllib_asor.rllib.connector import even_share, even_share_inputs, gather_batches, rank_and_size
from rllib_asor.rllib.learners import AsorLearnerMixin
from rllib_asor.rllib.modules import LABEL, proxy_batch


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
    mask = valid.reshape(-1).bool()  # the discriminator sees the valid steps only
    flat = obs.reshape(-1, obs.shape[-1])[mask]
    flat_next = next_obs.reshape(-1, obs.shape[-1])[mask]
    b = bonus_for_rows(
        cfg, state, result.lam, flat, flat_next, terminateds.reshape(-1)[mask], real.gamma
    )
    delta = torch.zeros(mask.shape, dtype=b.dtype, device=b.device)
    delta[mask] = b
    delta = delta.reshape(obs.shape[:-1])
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


class AsorMapleTorchLearner(AsorLearnerMixin, MapleTorchLearner):
    """MAPLE's Learner with ASOR: before each SAC step, the batch's real transitions
    (`real_*` columns, written by `MAPLE.training_step`) are ranked by V(s) = min Q(s, π(s))
    with their GRU contexts and by the visitation proxy; the discriminator and the proxy
    train on them in the same update; every segment step (real and model) gets λ·b(s) in
    the `asor_bonus` column, which MAPLE's loss adds to the rewards. Offline: λ's timestep
    is the number of real rows ranked so far (not checkpointed)."""

    asor_in_pipeline = False

    def build(self) -> None:
        super().build()
        self._asor_offline_rows = 0
        self._maple_asor_rng = np.random.default_rng(self.asor.seed)

    def _update(self, batch: dict, **kwargs: object) -> object:
        for pid, ids in self._asor_piece.aux_ids.items():
            if pid not in batch:
                continue
            pb = batch[pid]
            nets = self.module[pid].unwrapped().nets
            values = state_values(
                nets,
                pb["real_obs"],
                pb["real_last_actions"],
                pb["real_policy_hidden"],
                pb["real_value_hidden"],
            )
            real = real_batch(
                pb["real_obs"],
                pb["real_next_obs"],
                pb["real_rewards"].float(),
                pb["real_terminateds"].bool(),
                values,
                gamma=float(self.config.gamma),
                timestep=float(self._asor_offline_rows),
                actions=pb["real_actions"],
                dynamics_ids=pb["real_dynamics_ids"].long(),
            )
            state = self.module[ids.disc].unwrapped().state
            proxy = self.module[ids.proxy].unwrapped().proxy if ids.proxy is not None else None
            rank, size = rank_and_size()
            if size > 1:  # the same ASOR update on every Learner (connector.gather_batches)
                real = concat_batches([b for b in gather_batches(real, pb["obs"].device) if b])
            delta, result = maple_asor_bonus(
                self.asor,
                state,
                proxy,
                real,
                pb["obs"],
                pb["next_obs"],
                pb["terminateds"].bool(),
                pb["valid"].bool(),
                self._maple_asor_rng,
            )
            pb[BONUS] = delta
            batch[ids.disc] = {
                Columns.OBS: even_share(result.disc_features, rank, size),
                LABEL: even_share(result.disc_labels, rank, size),
            }
            if ids.proxy is not None:
                batch[ids.proxy] = proxy_batch(even_share_inputs(real.proxy_inputs, rank, size))
            if result.metrics:
                self.metrics.log_dict(result.metrics, key=ids.disc, window=1)
            self._asor_offline_rows += int(real.features.shape[0])
        return super()._update(batch, **kwargs)
