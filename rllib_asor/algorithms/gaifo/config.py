"""`GaifoConfig` / `GAIfO`: GAIfO as an RLlib algorithm (PPO with GAIfO's Learner).

    from rllib_asor import GaifoConfig
    config = (GaifoConfig()
              .environment("rllib_asor/LavaWorld-v0", env_config={"obs_mode": "onehot"})
              .gaifo(demonstrations="lava-expert.npz"))
    algo = config.build_algo()                         # GAIfO
    algo = rllib_asor.with_asor(config).build_algo()   # GAIfO + ASOR (ASOR's bonus on top)

A `PPOConfig` whose `.gaifo(...)` sets `GaifoSettings`. Its default Learner is RLlib's PPO
Learner, which the `GAIfO` algorithm swaps for `GaifoPPOTorchLearner` when built (and
with_asor's PPO Learner for the same with GAIfO mixed in), so `with_asor` finds PPO's ASOR
Learner for it.
"""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym
from ray.rllib.algorithms.ppo import PPO, PPOConfig
from ray.rllib.algorithms.ppo.torch.ppo_torch_learner import PPOTorchLearner

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.common.demonstrations import load_demonstrations
from rllib_asor.algorithms.gaifo.learner import (
    NO_DEMOS,
    demonstration_space,
    resolve_path,
    with_gaifo,
)
from rllib_asor.algorithms.gaifo.settings import GaifoSettings


class GaifoConfig(PPOConfig):
    """`PPOConfig` with GAIfO's settings (`.gaifo(...)`, `GaifoSettings`)."""

    def __init__(self, algo_class: type | None = None) -> None:
        super().__init__(algo_class=algo_class or GAIfO)
        self.gaifo_settings: dict[str, Any] = GaifoSettings().to_dict()

    def gaifo(self, **settings: Any) -> GaifoConfig:
        """Set GAIfO's settings (fields of `GaifoSettings`; `demonstrations` a path, made
        absolute here); ValueError names a bad key/value."""
        path = settings.get("demonstrations")
        if isinstance(path, os.PathLike | str):
            settings["demonstrations"] = os.path.abspath(os.fspath(path))
        self.gaifo_settings = GaifoSettings.from_dict(
            {**self.gaifo_settings, **settings}
        ).to_dict()
        return self

    def get_default_learner_class(self) -> type:
        """PPO's: the `GAIfO` algorithm mixes GAIfO in when built (`gaifo_learner`)."""
        return PPOTorchLearner

    def validate(self) -> None:
        super().validate()
        settings = GaifoSettings.from_dict(self.gaifo_settings)
        if not settings.demonstrations:
            raise ValueError(NO_DEMOS)
        check_demonstrations(self, settings)


def check_demonstrations(config: Any, settings: GaifoSettings) -> None:
    """Load the demonstrations once against a registered env's observation space (one
    ValueError naming the path and the problem); other envs are checked by the Learner."""
    if not isinstance(config.env, str) or config.env not in gym.registry:
        return
    env = gym.make(config.env, **dict(config.env_config or {}))
    try:
        space = env.observation_space
    finally:
        env.close()
    load_demonstrations(resolve_path(settings.demonstrations), demonstration_space(space, settings))


def gaifo_learner(config: Any) -> Any:
    """A copy of `config` whose Learner has GAIfO mixed in (PPO's, or with_asor's)."""
    config = config.copy(copy_frozen=False)
    base = compat.user_learner_class(config) or PPOTorchLearner
    config.learners(learner_class=with_gaifo(base))
    return config


class GAIfO(PPO):
    """PPO with GAIfO's Learner (its discriminator and reward)."""

    def __init__(self, config: Any = None, *args: Any, **kwargs: Any) -> None:
        if isinstance(config, dict):
            config = self.get_default_config().update_from_dict(config)
        if config is not None:
            config = gaifo_learner(config)
        super().__init__(config, *args, **kwargs)

    @classmethod
    def get_default_config(cls) -> GaifoConfig:
        return GaifoConfig()
