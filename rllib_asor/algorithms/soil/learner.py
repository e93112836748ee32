"""SOIL's Learner mixin: owns `SoilImitation` (the expert rows and the inverse dynamics model),
adds its demonstration term to the policy's loss, and keeps it in the Learner's state
(checkpoints).

Online (PPO) the model learns from each batch through `SoilIdmPiece`, right after the batch
became tensors (`NumpyToTensor`; before GAE and before ASOR's piece when ASOR is on). Offline
(MARWIL, `input_` set) RLlib's connector pipeline never sees the dataset's episodes in order,
so the model is fitted once, when the Learner is built, on the dataset's own transitions
(`idm_steps` minibatches), and labels the experts once.
"""

from __future__ import annotations

from typing import Any

import torch.distributed as dist
from ray.rllib.algorithms.marwil.torch.marwil_torch_learner import MARWILTorchLearner
from ray.rllib.algorithms.ppo.torch.ppo_torch_learner import PPOTorchLearner
from ray.rllib.connectors.common import NumpyToTensor
from ray.rllib.core.columns import Columns

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.common.demonstrations import load_demonstrations, resolve_path
from rllib_asor.algorithms.common.ifo_data import dataset_transitions, offline_parts
from rllib_asor.algorithms.soil.connector import METRICS_KEY, SoilIdmPiece
from rllib_asor.algorithms.soil.imitation import SoilImitation
from rllib_asor.algorithms.soil.settings import SoilSettings

STATE_KEY = "soil_imitation"
"""Key of SOIL's state in the Learner's state."""
NO_DEMOS = (
    "SOIL needs expert demonstrations: set soil.demonstrations (YAML) or "
    "SoilConfig().soil(demonstrations=PATH) to an .npz of state-only transitions or a "
    "`rllib data collect` dataset dir"
)


class SoilLearnerMixin:
    """SOIL's demonstration term and inverse dynamics model; mix in before a PPO or MARWIL
    Learner (module docstring)."""

    def build(self) -> None:
        super().build()  # type: ignore[misc]
        settings = SoilSettings.from_dict(getattr(self.config, "soil_settings", None))  # type: ignore[attr-defined]
        if not settings.demonstrations:
            raise ValueError(NO_DEMOS)
        self._soil_ids = tuple(
            mid
            for mid in self.module.keys()  # type: ignore[attr-defined]
            if self.should_module_be_updated(mid)  # type: ignore[attr-defined]
            and not mid.startswith("asor_")
        )
        policy = self.module[self._soil_ids[0]].unwrapped()  # type: ignore[attr-defined]
        demos = load_demonstrations(resolve_path(settings.demonstrations), policy.observation_space)
        rank = dist.get_rank() if dist.is_available() and dist.is_initialized() else 0
        batch = self.config.train_batch_size_per_learner  # type: ignore[attr-defined]
        self.soil = SoilImitation(
            settings,
            demos,
            policy.action_space,
            batch,
            self.device,  # type: ignore[attr-defined]
            rank,
        )
        parts = offline_parts(self.config)  # type: ignore[attr-defined]
        if parts:
            self.soil.observe(*dataset_transitions(parts))
            return
        pipeline = compat.learner_connector(self)
        if pipeline is None:
            raise ValueError(
                "SOIL needs the Learner connector pipeline; set num_aggregator_actors_per_learner=0"
            )
        if not any(isinstance(c, NumpyToTensor) for c in pipeline.connectors):
            raise ValueError(
                "SOIL's piece reads the Learner's tensor batch, and this Learner pipeline has no "
                "NumpyToTensor (keep add_default_connectors_to_learner_pipeline=True)"
            )
        piece = SoilIdmPiece(imitation=self.soil, module_ids=self._soil_ids)
        pipeline.insert_after(NumpyToTensor, piece)

    def compute_loss_for_module(
        self, *, module_id: str, config: Any, batch: dict[str, Any], fwd_out: dict[str, Any]
    ) -> Any:
        loss = super().compute_loss_for_module(  # type: ignore[misc]
            module_id=module_id, config=config, batch=batch, fwd_out=fwd_out
        )
        if module_id not in self._soil_ids:
            return loss
        module = self.module[module_id].unwrapped()  # type: ignore[attr-defined]
        term, stats = self.soil.loss(module, int(batch[Columns.OBS].shape[0]))
        if stats:
            self.metrics.log_dict(  # type: ignore[attr-defined]
                {**stats, "demo_loss": float(term.detach())}, key=METRICS_KEY, window=1
            )
        return loss + term

    def after_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        super().after_gradient_based_update(timesteps=timesteps)  # type: ignore[misc]
        self.soil.iteration += 1

    def get_state(self, *args: Any, **kwargs: Any) -> dict[str, Any]:
        state = super().get_state(*args, **kwargs)  # type: ignore[misc]
        if getattr(self, "soil", None) is not None:
            state[STATE_KEY] = self.soil.get_state()
        return state

    def set_state(self, state: dict[str, Any]) -> None:
        super().set_state(state)  # type: ignore[misc]
        if STATE_KEY in state and getattr(self, "soil", None) is not None:
            self.soil.set_state(state[STATE_KEY])


class SoilPPOTorchLearner(SoilLearnerMixin, PPOTorchLearner):
    """RLlib's PPO Learner with SOIL's inverse dynamics model and demonstration term."""


class SoilMARWILTorchLearner(SoilLearnerMixin, MARWILTorchLearner):
    """RLlib's MARWIL Learner with SOIL's demonstration term (offline SOIL)."""


_WITH_SOIL: dict[type, type] = {
    PPOTorchLearner: SoilPPOTorchLearner,
    MARWILTorchLearner: SoilMARWILTorchLearner,
}


def with_soil(learner: type) -> type:
    """`learner` (PPO's, MARWIL's, or with_asor's on them) with SOIL mixed in first:
    `Soil<name>`, made once per class."""
    if issubclass(learner, SoilLearnerMixin):
        return learner
    if learner not in _WITH_SOIL:
        doc = f"{learner.__name__} with SOIL's demonstration term (soil/learner.py)."
        _WITH_SOIL[learner] = type(
            "Soil" + learner.__name__, (SoilLearnerMixin, learner), {"__doc__": doc}
        )
    return _WITH_SOIL[learner]
