"""ASOR's learner-only RLModule: one per trained policy, holding that policy's `AsorTrainer`.

The module is a container, not a trained RLlib module: RLlib builds it on each Learner (never on
env runners: `learner_only`), places it on the Learner's device and checkpoints it with the
policy's modules; ASOR's connector piece trains what it holds (`rllib_asor.asor.trainer`: the
discriminator, the visitation proxy, their optimisers) once per train batch, outside RLlib's
minibatch loop. No Learner optimiser, loss or batch column is registered for it.
"""

from __future__ import annotations

from typing import Any

from ray.rllib.core.rl_module.torch import TorchRLModule

from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.networks import flat_dim, select_space
from rllib_asor.asor.trainer import AsorTrainer

TRAINER_STATE = "asor_trainer"
"""The module state's one key: `AsorTrainer.get_state()`."""
RETIRED_CLASSES = ("AsorDiscriminatorModule", "AsorProxyModule")
"""ASOR's module classes before `AsorModule`: a checkpoint that names one is older than it."""
OLDER_CHECKPOINT = (
    "written by an older rllib-asor (ASOR's discriminator and proxy were separate RLlib modules "
    "then) and cannot be restored by this version; allowed: a checkpoint written by this "
    "version, or train again"
)


class AsorModule(TorchRLModule):
    """`trainer`: the policy's `AsorTrainer`, built from `model_config["asor"]` with the
    policy's spaces (features: the key-selected, flattened observation)."""

    def setup(self) -> None:
        asor = AsorConfig.from_dict(self.model_config["asor"])
        self.feature_dim = flat_dim(select_space(self.observation_space, asor.obs_keys))
        self.trainer = AsorTrainer(asor, self.feature_dim, flat_dim(self.action_space), asor.seed)

    def _forward(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        raise NotImplementedError(f"{type(self).__name__} is learner-only: ASOR's piece uses it")

    def get_state(self, *args: Any, inference_only: bool = False, **kwargs: Any) -> dict:
        """The trainer's state; empty with `inference_only` (RLlib asks for that only to send
        weights to env runners, which never hold this module: on the race the archive alone
        was about 12 MB a sync)."""
        if inference_only:
            return {}
        return {TRAINER_STATE: self.trainer.get_state()}

    def set_state(self, state: dict) -> None:
        """Restore the trainer (any device); a state of an older layout is refused in one line."""
        if not state:
            return
        self.trainer.set_state(state.get(TRAINER_STATE))
