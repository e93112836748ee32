"""What the ASOR learner-connector piece asks of an algorithm, answered by one small adapter per
algorithm (`algorithms/<name>/asor_adapter.py`, beside its Learner).

The piece (`rllib_asor.rllib.connector.AsorRewardConnector`) is the same for every algorithm;
an adapter says only what differs: which value ranks the states, which rows are ranked (the
real ones), where the reward goes and where the piece sits. No ASOR import here: the algorithm
knows nothing of the method, the glue reads these answers.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch

DYNAMICS_ID = "asor_dynamics_id"
"""Column of each step's `info["dynamics_id"]` (`rnd_per_dynamics`), in a batch and in
`ranked_columns`."""


class AsorAdapter:
    """The defaults: every row of the train batch is ranked and gets λ·b(s) on its reward."""

    insert_before: type | None = None
    """The Learner-connector piece that ASOR's piece must precede (None: the pipeline's end)."""
    in_pipeline: bool = True
    """False where train batches bypass the Learner connector (offline dataset batches,
    MAPLE's own batches): the Learner applies the piece at the start of its update, and λ's
    timestep is the number of rows ranked so far."""
    shares_values_with_gae: bool = False
    """The ranking values are the critic's V(s) that GAE computes next (reused, not recomputed)."""
    bonus_column: str | None = None
    """None: λ·b is added to the ranked rows' rewards (before GAE, or before the TD target).
    A column: the ranked rows only train the discriminator, and λ·b of every valid row of
    `bonus_rows` is written into this column, which the algorithm's loss adds to the rewards."""

    def state_values(self, module: Any, batch: dict[str, Any]) -> torch.Tensor:
        """V(s) of every ranked row (no gradient needed), from the module's own critic."""
        raise NotImplementedError

    ranked_columns: Callable[[dict[str, Any]], dict[str, Any]] | None = None
    """None: the policy's own rows are ranked. Else the ranked rows as RLlib columns (OBS,
    REWARDS, TERMINATEDS, NEXT_OBS, ACTIONS, LOSS_MASK where present, `DYNAMICS_ID`) of a
    policy batch."""

    def bonus_rows(self, batch: dict[str, Any]) -> dict[str, Any]:
        """With `bonus_column`: the rows that get the bonus, `[..., D]` OBS and NEXT_OBS,
        `[...]` TERMINATEDS and "valid" (False: padding, left at 0)."""
        raise NotImplementedError
