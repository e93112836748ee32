"""`SoilConfig` / `SOIL`: SOIL as an RLlib algorithm, online on PPO, offline on MARWIL.

    from rllib_asor import SoilConfig
    config = (SoilConfig()
              .environment("rllib_asor/LavaWorld-v0", env_config={"obs_mode": "onehot"})
              .soil(demonstrations="lava-expert.npz"))
    algo = config.build_algo()                         # SOIL (PPO + demonstration term)
    algo = rllib_asor.with_asor(config).build_algo()   # SOIL + ASOR

A `PPOConfig` whose `.soil(...)` sets `SoilSettings`. Its default Learner is RLlib's PPO
Learner, which the `SOIL` algorithm swaps for `SoilPPOTorchLearner` when built (and with_asor's
PPO Learner for the same with SOIL mixed in), so `with_asor` finds PPO's ASOR Learner for it.

Offline (the paper's Table 1): `SoilOfflineConfig` (a `MARWILConfig`, RLlib's offline
policy-gradient-like algorithm, with `.soil(...)`) and `SOILOffline`; `run: SOIL` with `input:`
in a YAML file builds that one (`SOIL.offline_variant`). It evaluates itself on the data's
dynamics every `soil.evaluation_interval` iterations (`evaluation/<dynamics>/...`, as MAPLE).
"""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym
from ray.rllib.algorithms.marwil import MARWIL, MARWILConfig
from ray.rllib.algorithms.marwil.torch.marwil_torch_learner import MARWILTorchLearner
from ray.rllib.algorithms.ppo import PPO, PPOConfig
from ray.rllib.algorithms.ppo.torch.ppo_torch_learner import PPOTorchLearner

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.common.demonstrations import load_demonstrations, resolve_path
from rllib_asor.algorithms.common.ifo_data import evaluate_on_data, offline_parts
from rllib_asor.algorithms.soil.learner import NO_DEMOS, with_soil
from rllib_asor.algorithms.soil.settings import SoilSettings


class _SoilSettingsMixin:
    """`.soil(...)` and its validation, for SOIL's online and offline configs."""

    soil_settings: dict[str, Any]

    def soil(self, **settings: Any) -> Any:
        """Set SOIL's settings (fields of `SoilSettings`; `demonstrations` a path, made
        absolute here); ValueError names a bad key/value."""
        path = settings.get("demonstrations")
        if isinstance(path, os.PathLike | str):
            settings["demonstrations"] = os.path.abspath(os.fspath(path))
        self.soil_settings = SoilSettings.from_dict({**self.soil_settings, **settings}).to_dict()
        return self

    def _validate_soil(self) -> None:
        settings = SoilSettings.from_dict(self.soil_settings)
        if not settings.demonstrations:
            raise ValueError(NO_DEMOS)
        env = getattr(self, "env", None)
        path = resolve_path(settings.demonstrations)
        # other envs, and missing files (the CLI's and the Learner's error): checked by the Learner
        if os.path.exists(path) and isinstance(env, str) and env in gym.registry:
            made = gym.make(env, **dict(getattr(self, "env_config", None) or {}))
            try:
                space = made.observation_space
            finally:
                made.close()
            load_demonstrations(path, space)


class SoilConfig(_SoilSettingsMixin, PPOConfig):
    """`PPOConfig` with SOIL's settings (`.soil(...)`, `SoilSettings`)."""

    def __init__(self, algo_class: type | None = None) -> None:
        super().__init__(algo_class=algo_class or SOIL)
        self.soil_settings: dict[str, Any] = SoilSettings().to_dict()

    def get_default_learner_class(self) -> type:
        """PPO's: the `SOIL` algorithm mixes SOIL in when built (`soil_learner`)."""
        return PPOTorchLearner

    def validate(self) -> None:
        super().validate()
        if offline_parts(self):
            raise ValueError(
                "SoilConfig is SOIL online (PPO); with offline input use SoilOfflineConfig "
                "(MARWIL), or `run: SOIL` with `input:` in a YAML file"
            )
        self._validate_soil()


class SoilOfflineConfig(_SoilSettingsMixin, MARWILConfig):
    """`MARWILConfig` with SOIL's settings: SOIL's demonstration term on MARWIL's loss, the
    inverse dynamics model fitted on the dataset (`input_`, `rllib data collect` parts)."""

    def __init__(self, algo_class: type | None = None) -> None:
        super().__init__(algo_class=algo_class or SOILOffline)
        self.soil_settings: dict[str, Any] = SoilSettings().to_dict()

    def get_default_learner_class(self) -> type:
        return MARWILTorchLearner

    def validate(self) -> None:
        with_env_spaces(self)  # RLlib's offline check wants them when nothing is evaluated
        super().validate()
        if not offline_parts(self):
            raise ValueError(
                "SoilOfflineConfig needs offline data: .offline_data(input_=[part dirs such as "
                "'data/offline/hopper/original/medium']); online SOIL is SoilConfig"
            )
        self._validate_soil()


def soil_learner(config: Any) -> Any:
    """A copy of `config` whose Learner has SOIL mixed in (PPO's, MARWIL's, or with_asor's)."""
    config = config.copy(copy_frozen=False)
    base = compat.user_learner_class(config) or config.get_default_learner_class()
    config.learners(learner_class=with_soil(base))
    return config


def with_env_spaces(config: Any) -> Any:
    """`config` with the env's observation and action spaces set where it has none (RLlib's
    offline algorithms need them when they evaluate nothing); the env must be a registered id."""
    if config.observation_space is not None and config.action_space is not None:
        return config
    if not isinstance(config.env, str) or config.env not in gym.registry:
        return config
    env = gym.make(config.env, **dict(config.env_config or {}))
    try:
        config.environment(observation_space=env.observation_space, action_space=env.action_space)
    finally:
        env.close()
    return config


class SOILOffline(MARWIL):
    """MARWIL with SOIL's demonstration term; evaluates itself on the data's dynamics."""

    def __init__(self, config: Any = None, *args: Any, **kwargs: Any) -> None:
        if isinstance(config, dict):
            config = self.get_default_config().update_from_dict(config)
        if config is not None:
            config = with_env_spaces(soil_learner(config))
        super().__init__(config, *args, **kwargs)

    @classmethod
    def get_default_config(cls) -> SoilOfflineConfig:
        return SoilOfflineConfig()

    def training_step(self) -> None:
        super().training_step()
        s = SoilSettings.from_dict(self.config.soil_settings)
        if s.evaluation_interval and (self.iteration + 1) % s.evaluation_interval == 0:
            flat = evaluate_on_data(self, s.evaluation_episodes)
            if flat:
                self.metrics.log_dict(flat, key="evaluation", window=1)


class SOIL(PPO):
    """PPO with SOIL's Learner (its inverse dynamics model and demonstration term)."""

    offline_variant = SOILOffline
    """The algorithm `run: SOIL` builds when the YAML config has `input:` (offline)."""

    def __init__(self, config: Any = None, *args: Any, **kwargs: Any) -> None:
        if isinstance(config, dict):
            config = self.get_default_config().update_from_dict(config)
        if config is not None:
            config = soil_learner(config)
        super().__init__(config, *args, **kwargs)

    @classmethod
    def get_default_config(cls) -> SoilConfig:
        return SoilConfig()
