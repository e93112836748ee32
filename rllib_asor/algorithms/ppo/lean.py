"""PPO's Learner without its masked bootstrap rows (opt-in, `learner_config_dict`).

RLlib's PPO elongates every episode chunk by one artificial step so that GAE can take the
bootstrap value at the cut in the same critic forward pass; the step then stays in the train
batch with `loss_mask=False`. With 16 envs a 1,024-step batch becomes 1,040 rows, so 4 epochs of
256-row minibatches make 17 minibatches instead of 16, each a little under 256 valid rows, and
~6 % of the Learner's forward and backward passes are spent on rows no loss reads.
`DropMaskedRows` removes them once GAE is done: every valid row is then trained on exactly
`num_epochs` times in full minibatches (16 Adam steps instead of 17 on the race). That is a
small change of PPO's schedule, so it is off by default:

    learner_config_dict: {drop_bootstrap_rows: true}

or `drop_bootstrap_rows(config)`. Recurrent modules keep their rows (their batch is [B, T]).
"""

from __future__ import annotations

from typing import Any

import torch
import tree
from ray.rllib.algorithms.algorithm_config import AlgorithmConfig
from ray.rllib.algorithms.ppo import PPO
from ray.rllib.algorithms.ppo.torch.ppo_torch_learner import PPOTorchLearner
from ray.rllib.connectors.connector_v2 import ConnectorV2
from ray.rllib.connectors.learner import GeneralAdvantageEstimation
from ray.rllib.core.columns import Columns

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.common.learner_speed import SameMathSpeedMixin, take_rows
from rllib_asor.algorithms.common.pipeline import insert_beside
from rllib_asor.algorithms.ppo.loss import SyncFreePPOLossMixin

DROP_KEY = "drop_bootstrap_rows"
"""`learner_config_dict` key that switches the row drop on."""


def drop_enabled(config: AlgorithmConfig) -> bool:
    """Whether `config` asks for PPO's masked rows to be dropped after GAE."""
    return bool((config.learner_config_dict or {}).get(DROP_KEY, False))


def drop_bootstrap_rows(config: AlgorithmConfig, enabled: bool = True) -> AlgorithmConfig:
    """A copy of the PPO `config` whose Learner drops the masked bootstrap rows after GAE.

    Plain PPO gets `LeanPPOTorchLearner`; a config with ASOR gets ASOR on that Learner (its
    Learner class says which: `asor_learner_on`), so either order of `with_asor` and this works."""
    if config.algo_class is None or not issubclass(config.algo_class, PPO):
        name = getattr(config.algo_class, "__name__", type(config).__name__)
        raise ValueError(f"drop_bootstrap_rows needs a PPO config, got {name}")
    config = config.copy(copy_frozen=False)
    learner = compat.user_learner_class(config)
    if learner is None:
        config.learners(learner_class=LeanPPOTorchLearner)
    elif learner.__bases__[-1] is PPOTorchLearner and hasattr(learner, "asor_learner_on"):
        config.learners(learner_class=learner.asor_learner_on(LeanPPOTorchLearner))
    elif not issubclass(learner, LeanPPOMixin):
        raise ValueError(
            f"drop_bootstrap_rows: the Learner class {learner.__name__} would "
            "ignore it; mix rllib_asor.algorithms.ppo.lean.LeanPPOMixin into it (before PPO's Learner) "
            "or leave learner_class unset"
        )
    config.learners(learner_config_dict={**(config.learner_config_dict or {}), DROP_KEY: enabled})
    return config


class DropMaskedRows(ConnectorV2):
    """Learner connector piece (after GAE): keeps only the rows with `loss_mask=True` of each
    non-recurrent module and removes the mask column (every row left is valid)."""

    def __call__(self, *, rl_module: Any, batch: dict[str, Any], **kwargs: Any) -> Any:
        for module_id, module_batch in batch.items():
            if Columns.LOSS_MASK not in module_batch or rl_module[module_id].is_stateful():
                continue
            mask = module_batch.pop(Columns.LOSS_MASK)
            if bool(mask.all()):
                continue
            index = torch.nonzero(mask, as_tuple=True)[0]
            batch[module_id] = tree.map_structure(lambda x, i=index: take_rows(x, i), module_batch)
        return batch


class LeanPPOMixin(SyncFreePPOLossMixin):
    """Inserts `DropMaskedRows` after GAE when `learner_config_dict[DROP_KEY]` is set, and
    computes PPO's loss without host syncs (`SyncFreePPOLossMixin`: RLlib's formulas). Mix in
    before the PPO Learner (and after ASOR's mixin, whose piece must see the full batch)."""

    def build(self) -> None:
        super().build()  # type: ignore[misc]
        if not drop_enabled(self.config):  # type: ignore[attr-defined]
            return
        pipeline = compat.learner_connector(self)
        if pipeline is None:
            raise ValueError(
                f"{DROP_KEY} needs the Learner connector pipeline; "
                "set num_aggregator_actors_per_learner=0"
            )
        piece = DropMaskedRows()
        insert_beside(pipeline, GeneralAdvantageEstimation, piece, before=False)


class LeanPPOTorchLearner(SameMathSpeedMixin, LeanPPOMixin, PPOTorchLearner):
    """RLlib's PPO Learner with this package's same-math speed-ups (the race's PPO Learner)
    that can also drop the masked bootstrap rows (`drop_bootstrap_rows`)."""
