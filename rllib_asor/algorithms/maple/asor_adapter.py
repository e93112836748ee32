"""MAPLE's answers to the ASOR piece, as the paper ("the procedure of MAPLE+ASOR is similar to
ESCP+ASOR, where the datasets are built with data from the offline dataset") and SRPO's MAPLE
code (`AIDefender/SRPO offlinerl/algo/modelbase/maple_st.py train_policy`) do it:

- the ranked rows are a separate batch of *real* dataset transitions (the `real_*` columns
  that `MAPLE.training_step` writes), ranked by V(s) = min(Q1, Q2)(s, π(s)) with their GRU
  contexts;
- the bonus λ·b(s) goes to every valid step of the SAC batch, real and model segments alike,
  in the `asor_bonus` column that MAPLE's loss adds to the rewards (SRPO adds
  η·log(clamp(logit, 0.1, 10)) to every row's Q target).

MAPLE's batches bypass the Learner connector: the Learner applies the piece to each batch.
"""

from __future__ import annotations

from typing import Any

import torch
from ray.rllib.core.columns import Columns

from rllib_asor.algorithms.common.asor_adapter import DYNAMICS_ID, AsorAdapter
from rllib_asor.algorithms.maple.learner import BONUS
from rllib_asor.algorithms.maple.losses import state_values


class MapleAsorAdapter(AsorAdapter):
    """MAPLE / MOPO: real rows ranked, the bonus on every segment step."""

    in_pipeline = False
    bonus_column = BONUS

    def state_values(self, module: Any, batch: dict[str, Any]) -> torch.Tensor:
        return state_values(
            module.nets,
            batch["real_obs"],
            batch["real_last_actions"],
            batch["real_policy_hidden"],
            batch["real_value_hidden"],
        )

    def ranked_columns(self, batch: dict[str, Any]) -> dict[str, Any]:
        return {
            Columns.OBS: batch["real_obs"],
            Columns.NEXT_OBS: batch["real_next_obs"],
            Columns.ACTIONS: batch["real_actions"],
            Columns.REWARDS: batch["real_rewards"].float(),
            Columns.TERMINATEDS: batch["real_terminateds"].bool(),
            DYNAMICS_ID: batch["real_dynamics_ids"].long(),
        }

    def bonus_rows(self, batch: dict[str, Any]) -> dict[str, Any]:
        return {
            Columns.OBS: batch["obs"],
            Columns.NEXT_OBS: batch["next_obs"],
            Columns.TERMINATEDS: batch["terminateds"].bool(),
            "valid": batch["valid"].bool(),
        }
