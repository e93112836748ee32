"""GAIfO's Learner: a PPO Learner that owns the discriminator (`GaifoTrainer`, its own Adam)
and puts GAIfO's reward piece into its Learner connector right after NumpyToTensor, i.e. before
GAE and before ASOR's piece when ASOR is on (ASOR's bonus is added to the imitation reward).
Its state (checkpoints) carries the discriminator, its optimizer and the sampling rng."""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym
import torch.distributed as dist
from ray.rllib.algorithms.ppo.torch.ppo_torch_learner import PPOTorchLearner
from ray.rllib.connectors.common import NumpyToTensor

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.common.demonstrations import load_demonstrations
from rllib_asor.algorithms.common.pipeline import insert_beside
from rllib_asor.algorithms.gaifo.connector import GaifoRewardPiece
from rllib_asor.algorithms.gaifo.settings import GaifoSettings
from rllib_asor.algorithms.gaifo.trainer import GaifoTrainer

STATE_KEY = "gaifo_discriminator"
"""Key of the discriminator's state in the Learner's state."""
NO_DEMOS = (
    "GAIfO needs expert demonstrations: set gaifo.demonstrations (YAML) or "
    "GaifoConfig().gaifo(demonstrations=PATH) to an .npz of state-only transitions or a "
    "`rllib data collect` dataset dir"
)


def resolve_path(path: str) -> str:
    """`path`, or relative to the directory Tune started in (trials run in their own)."""
    if os.path.isabs(path) or os.path.exists(path):
        return path
    start = os.environ.get("TUNE_ORIG_WORKING_DIR")
    return os.path.join(start, path) if start else path


def demonstration_space(space: gym.Space, settings: GaifoSettings) -> gym.Space:
    """The space the demonstrations' observations must have: the env's, or its first
    `state_dims` features (`disc_input: s_next`; the `obs_*` inputs read the whole one)."""
    if settings.state_dims is None or settings.disc_input != "s_next":
        return space
    return gym.spaces.Box(-float("inf"), float("inf"), (settings.state_dims,))


class GaifoLearnerMixin:
    """Builds GAIfO's discriminator and piece; mix in before a PPO Learner."""

    def build(self) -> None:
        super().build()  # type: ignore[misc]
        settings = GaifoSettings.from_dict(getattr(self.config, "gaifo_settings", None))
        if not settings.demonstrations:
            raise ValueError(NO_DEMOS)
        ids = tuple(
            mid
            for mid in self.module.keys()  # type: ignore[attr-defined]
            if self.should_module_be_updated(mid)  # type: ignore[attr-defined]
            and not mid.startswith("asor_")
        )
        space = self.module[ids[0]].unwrapped().observation_space  # type: ignore[attr-defined]
        demos = load_demonstrations(
            resolve_path(settings.demonstrations), demonstration_space(space, settings)
        )
        rank = dist.get_rank() if dist.is_available() and dist.is_initialized() else 0
        self.gaifo = GaifoTrainer(settings, demos, self.device, rank)  # type: ignore[attr-defined]
        pipeline = compat.learner_connector(self)
        if pipeline is None:
            raise ValueError(
                "GAIfO needs the Learner connector pipeline; set num_aggregator_actors_per_learner=0"
            )
        # Right after NumpyToTensor: before GAE and before ASOR's piece (which sits right
        # before GAE), so ASOR's bonus is added to the imitation reward.
        insert_beside(
            pipeline, NumpyToTensor, GaifoRewardPiece(trainer=self.gaifo, module_ids=ids),
            before=False,
        )

    def get_state(self, *args: Any, **kwargs: Any) -> dict[str, Any]:
        state = super().get_state(*args, **kwargs)  # type: ignore[misc]
        if getattr(self, "gaifo", None) is not None:
            state[STATE_KEY] = self.gaifo.get_state()
        return state

    def set_state(self, state: dict[str, Any]) -> None:
        super().set_state(state)  # type: ignore[misc]
        if STATE_KEY in state and getattr(self, "gaifo", None) is not None:
            self.gaifo.set_state(state[STATE_KEY])


class GaifoPPOTorchLearner(GaifoLearnerMixin, PPOTorchLearner):
    """RLlib's PPO Learner with GAIfO's discriminator and reward (module docstring)."""


_WITH_GAIFO: dict[type, type] = {}


def with_gaifo(ppo_learner: type) -> type:
    """`ppo_learner` (e.g. with_asor's PPO Learner) with GAIfO mixed in first: `Gaifo<name>`,
    made once per class."""
    if issubclass(ppo_learner, GaifoLearnerMixin):
        return ppo_learner
    if ppo_learner is PPOTorchLearner:
        return GaifoPPOTorchLearner
    if ppo_learner not in _WITH_GAIFO:
        doc = f"{ppo_learner.__name__} with GAIfO's discriminator and reward (gaifo/learner.py)."
        _WITH_GAIFO[ppo_learner] = type(
            "Gaifo" + ppo_learner.__name__, (GaifoLearnerMixin, ppo_learner), {"__doc__": doc}
        )
    return _WITH_GAIFO[ppo_learner]
