"""Learner classes with ASOR: the algorithm's own Learner plus the ASOR connector piece.

`AsorLearnerMixin.build()` reads the validated settings from
`config.learner_config_dict["asor"]`, finds each trained policy's discriminator/proxy modules,
and inserts `AsorRewardConnector` at the algorithm's place (PPO: right before GAE). It also
gives the auxiliary modules their own Adam optimisers (learning rates from `AsorConfig`,
frozen RND target excluded).
"""

from __future__ import annotations

from typing import Any

import torch
from ray.rllib.algorithms.ppo.torch.ppo_torch_learner import PPOTorchLearner
from ray.rllib.connectors.common.add_observations_from_episodes_to_batch import (
    AddObservationsFromEpisodesToBatch,
)
from ray.rllib.connectors.learner import GeneralAdvantageEstimation
from ray.rllib.connectors.learner.add_next_observations_from_episodes_to_train_batch import (
    AddNextObservationsFromEpisodesToTrainBatch,
)
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

from rllib_asor.asor.config import AsorConfig
from rllib_asor.rllib.connector import AsorRewardConnector, AuxModuleIds

DISC_PREFIX = "asor_disc."
PROXY_PREFIX = "asor_proxy."


def disc_module_id(policy_id: str) -> str:
    """Module id of the discriminator that belongs to `policy_id`."""
    return DISC_PREFIX + policy_id


def proxy_module_id(policy_id: str) -> str:
    """Module id of the visitation-count proxy (RND/ensemble) of `policy_id`."""
    return PROXY_PREFIX + policy_id


def is_aux_module(module_id: str) -> bool:
    """Whether a module id names one of ASOR's auxiliary modules."""
    return module_id.startswith((DISC_PREFIX, PROXY_PREFIX))


class AsorLearnerMixin:
    """Adds the ASOR piece to a Learner's pipeline; mix in before the algorithm's Learner."""

    asor_insert_before: type | None = GeneralAdvantageEstimation
    """The piece ASOR must precede (None: append at the end of the pipeline)."""

    def build(self) -> None:
        super().build()  # type: ignore[misc]
        self.asor = AsorConfig.from_dict(self.config.learner_config_dict.get("asor"))
        self._asor_timestep = 0.0
        aux = {
            pid: AuxModuleIds(
                disc=disc_module_id(pid),
                proxy=proxy_module_id(pid) if self.asor.needs_proxy else None,
            )
            for pid in self.module.keys()
            if disc_module_id(pid) in self.module
        }
        if not aux:
            raise ValueError(
                "ASOR learner: no discriminator module found in the MultiRLModule; "
                "build the config with rllib_asor.with_asor(config, ...)"
            )
        pipeline = self._learner_connector
        if pipeline is None:
            raise ValueError(
                "ASOR needs the Learner connector pipeline; set num_aggregator_actors_per_learner=0"
            )
        if self.asor.proxy == "ensemble" and self.asor.needs_proxy:
            pipeline.insert_after(
                AddObservationsFromEpisodesToBatch, AddNextObservationsFromEpisodesToTrainBatch()
            )
        piece = AsorRewardConnector(
            asor=self.asor,
            aux_ids=aux,
            timestep_fn=lambda: self._asor_timestep,
            **self.asor_connector_kwargs(),
        )
        if self.asor_insert_before is None:
            pipeline.append(piece)
        else:
            pipeline.insert_before(self.asor_insert_before, piece)

    def asor_connector_kwargs(self) -> dict[str, Any]:
        """Extra keyword arguments for the connector (e.g. a `value_fn` for off-policy)."""
        return {}

    def before_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        super().before_gradient_based_update(timesteps=timesteps)  # type: ignore[misc]
        self._asor_timestep = float(timesteps.get(NUM_ENV_STEPS_SAMPLED_LIFETIME, 0) or 0)

    def configure_optimizers_for_module(self, module_id: str, config: Any = None) -> None:
        if not is_aux_module(module_id):
            return super().configure_optimizers_for_module(module_id, config)  # type: ignore[misc]
        asor = AsorConfig.from_dict(self.config.learner_config_dict.get("asor"))
        lr = asor.disc_lr if module_id.startswith(DISC_PREFIX) else asor.rnd_lr
        params = [p for p in self._module[module_id].parameters() if p.requires_grad]
        self.register_optimizer(
            module_id=module_id,
            optimizer=torch.optim.Adam(params),
            params=params,
            lr_or_lr_schedule=lr,
        )


class AsorPPOTorchLearner(AsorLearnerMixin, PPOTorchLearner):
    """PPO's torch Learner with ASOR's reward augmentation before GAE."""
