"""`GaratConfig` / `GARAT`: GARAT as an RLlib algorithm.

    from rllib_asor import GaratConfig
    config = (GaratConfig()
              .environment("Pendulum-v1", env_config={"g": 10.0})        # the source
              .garat(demonstrations="pendulum-g8-random.npz",             # the target's
                     target_env_config={"g": 8.0})                        # transitions
              .evaluation(evaluation_interval=1))
    algo = config.build_algo()      # grounds the source, then PPO in the grounded source
    algo = rllib_asor.with_asor(config).build_algo()   # GARAT's PPO step with ASOR

A `PPOConfig`; building the `GARAT` algorithm first runs the grounding step (`grounding.py`,
once: the transformer is kept in the config, so checkpoints restore without grounding again),
then trains PPO in `GroundedEnv` and evaluates in the target (`target_env_config`).
"""

from __future__ import annotations

import os
from typing import Any

from ray.rllib.algorithms.ppo import PPO, PPOConfig

from rllib_asor.algorithms.common.demonstrations import load_demonstrations
from rllib_asor.algorithms.gaifo.learner import resolve_path
from rllib_asor.algorithms.garat.envs import GroundedEnv, make_source
from rllib_asor.algorithms.garat.grounding import check_disc_input
from rllib_asor.algorithms.garat.settings import GaratSettings

NO_DEMOS = (
    "GARAT needs the target's transitions: set garat.demonstrations (YAML) or "
    "GaratConfig().garat(demonstrations=PATH) to an .npz of state-only transitions recorded "
    "in the target env by the behaviour policy (garat.behaviour_policy; none: random actions)"
)


class GaratConfig(PPOConfig):
    """`PPOConfig` with GARAT's settings (`.garat(...)`, `GaratSettings`)."""

    def __init__(self, algo_class: type | None = None) -> None:
        super().__init__(algo_class=algo_class or GARAT)
        self.garat_settings: dict[str, Any] = GaratSettings().to_dict()
        self.garat_grounded: dict[str, Any] | None = None
        """Set by the first build: source env, its env_config, the transformer, statistics."""

    def garat(self, **settings: Any) -> GaratConfig:
        """Set GARAT's settings (fields of `GaratSettings`; `demonstrations` a path, made
        absolute here); ValueError names a bad key/value."""
        for key in ("demonstrations", "behaviour_policy"):
            path = settings.get(key)
            if isinstance(path, os.PathLike | str):
                settings[key] = os.path.abspath(os.fspath(path))
        self.garat_settings = GaratSettings.from_dict(
            {**self.garat_settings, **settings}
        ).to_dict()
        return self

    def validate(self) -> None:
        super().validate()
        settings = GaratSettings.from_dict(self.garat_settings)
        if self.garat_grounded is not None:
            return
        if not isinstance(self.env, str):
            raise ValueError(
                f"GARAT needs the source env as a registered id (got {self.env!r}); allowed: a "
                "gymnasium id such as Pendulum-v1, its dynamics in env_config"
            )
        if not settings.demonstrations:
            raise ValueError(NO_DEMOS)
        source = make_source({"env": self.env, "env_config": self.env_config})
        try:
            space = source.observation_space
        finally:
            source.close()
        load_demonstrations(resolve_path(settings.demonstrations), space)
        policy = settings.behaviour_policy
        check_disc_input(settings, policy or None)
        if policy and not os.path.exists(resolve_path(policy)):
            raise ValueError(
                f"garat.behaviour_policy {policy} does not exist; allowed: an Algorithm's or an "
                "RLModule's checkpoint directory, or null (random actions)"
            )


def garat_grounded(config: Any) -> Any:
    """A copy of `config` on the grounded source (grounding first when not done yet), its
    evaluation env the target."""
    from rllib_asor.algorithms.garat.grounding import ground

    s = GaratSettings.from_dict(getattr(config, "garat_settings", None))
    config = config.copy(copy_frozen=False)
    if config.garat_grounded is None:
        config.validate()
        env, env_config = config.env, dict(config.env_config or {})
        behaviour = resolve_path(s.behaviour_policy) if s.behaviour_policy else None
        transformer, stats = ground(
            env, env_config, s, resolve_path(s.demonstrations), behaviour
        )
        config.garat_grounded = {
            "env": env,
            "env_config": env_config,
            "transformer": transformer,
            "stats": stats,
        }
    g = config.garat_grounded
    config.environment(
        GroundedEnv,
        env_config={
            "env": g["env"],
            "env_config": g["env_config"],
            "transformer": g["transformer"],
            "alpha": s.alpha,
        },
    )
    target = s.target_env_config if s.target_env_config is not None else g["env_config"]
    # The target: the same wrapper with no transformer (RLlib merges env_config overrides).
    user = dict(config.evaluation_config or {})
    user["env_config"] = {**dict(user.get("env_config") or {}), "env_config": dict(target),
                          "transformer": None}
    config.evaluation(evaluation_config=user)
    return config


class GARAT(PPO):
    """PPO in the grounded source (module docstring); `grounding` holds the grounding step's
    last statistics (also in every result under `garat/`)."""

    def __init__(self, config: Any = None, *args: Any, **kwargs: Any) -> None:
        if isinstance(config, dict):
            config = self.get_default_config().update_from_dict(config)
        if config is not None:
            config = garat_grounded(config)
        super().__init__(config, *args, **kwargs)

    @classmethod
    def get_default_config(cls) -> GaratConfig:
        return GaratConfig()

    def setup(self, config: Any) -> None:
        super().setup(config)
        s = GaratSettings.from_dict(self.config.garat_settings)
        if s.behaviour_policy and self.iteration == 0:
            self._start_from(resolve_path(s.behaviour_policy))

    def _start_from(self, path: str) -> None:
        """The policy starts as the behaviour policy π₀ (the authors' `--load_policy_path`)."""
        from ray.rllib.core import DEFAULT_MODULE_ID

        from rllib_asor.evaluation.rollout import policy_module

        state = policy_module(path).get_state()
        try:
            self.learner_group.foreach_learner(
                lambda learner: learner.module[DEFAULT_MODULE_ID].set_state(state)
            )
        except Exception as e:  # noqa: BLE001  (a shape mismatch, as one line)
            raise ValueError(
                f"garat.behaviour_policy {path}: its weights do not fit this config's policy "
                f"({str(e).splitlines()[0][:200]}); allowed: a checkpoint of the same model_config"
            ) from None
        self.env_runner_group.sync_weights(
            from_worker_or_learner_group=self.learner_group, inference_only=True
        )

    def training_step(self) -> None:
        super().training_step()
        stats = (self.config.garat_grounded or {}).get("stats") or {}
        if stats:
            self.metrics.log_dict(stats, key="garat", window=1)



