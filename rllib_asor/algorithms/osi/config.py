"""`OsiConfig` / `OSI`: UP-OSI as an RLlib algorithm, on ESCP's machinery.

    from rllib_asor.algorithms.osi.config import OsiConfig
    config = (OsiConfig()
              .environment("rllib_asor/Walker2dShift-v0", env_config={"num_tasks": 40})
              .osi(history_len=10))
    algo = config.build_algo()                         # UP-OSI
    algo = rllib_asor.with_asor(config).build_algo()   # UP-OSI + ASOR

An `EscpConfig` (SAC defaults of ESCP, the fast off-policy path, the window connector) whose
module is `OsiTorchRLModule` and whose Learner is `OsiTorchLearner`; `.osi(...)` sets
`OsiSettings`. The env must report `info["dynamics_params"]` (and `info["dynamics_id"]`, as for
ESCP); `param_dim` is read from one env reset when not set.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
from ray.rllib.core.rl_module.rl_module import RLModuleSpec

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.escp.config import ESCP, EscpConfig, escp_fast_path
from rllib_asor.algorithms.escp.learner import EscpTorchLearner
from rllib_asor.algorithms.escp.module import ESCP_KEY
from rllib_asor.algorithms.escp.settings import EscpSettings
from rllib_asor.algorithms.osi.learner import OsiLearnerMixin, OsiTorchLearner
from rllib_asor.algorithms.osi.module import OSI_KEY, OsiTorchRLModule
from rllib_asor.algorithms.osi.replay import OsiReplayBuffer, dynamics_params
from rllib_asor.algorithms.osi.settings import OsiSettings


class OsiConfig(EscpConfig):
    """`EscpConfig` with OSI's module, Learner and settings (`.osi(...)`, `OsiSettings`)."""

    def __init__(self, algo_class: type | None = None) -> None:
        super().__init__(algo_class=algo_class or OSI)
        self.osi_settings: dict[str, Any] = OsiSettings().to_dict()

    def osi(self, **settings: Any) -> OsiConfig:
        """Set OSI's settings (fields of `OsiSettings`); ValueError names a bad key/value."""
        self.osi_settings = OsiSettings.from_dict({**self.osi_settings, **settings}).to_dict()
        return self

    def param_dim(self) -> int:
        """`osi.param_dim`, or the length of `info["dynamics_params"]` of one env reset."""
        s = OsiSettings.from_dict(self.osi_settings)
        if s.param_dim is not None:
            return s.param_dim
        import rllib_asor.envs  # noqa: F401  (registers our env ids)

        if not isinstance(self.env, str):
            raise ValueError("OSI needs osi.param_dim when the env is not a registered id")
        env = gym.make(self.env, **dict(self.env_config or {}))
        try:
            _, info = env.reset(seed=0)
            return int(dynamics_params([info]).shape[1])
        finally:
            env.close()

    @property
    def _model_config_auto_includes(self) -> dict[str, Any]:
        s = OsiSettings.from_dict(self.osi_settings)
        escp = EscpSettings.from_dict(
            {
                **self.escp_settings,
                "context_dim": self.param_dim(),
                "history_len": s.history_len,
                "context_noise": 0.0,
                "encoder_lr": s.osi_lr,
                "target_entropy_ratio": s.target_entropy_ratio,
            }
        )
        return super()._model_config_auto_includes | {
            ESCP_KEY: escp.model_dump(),
            OSI_KEY: s.to_dict(),
        }

    def get_default_rl_module_spec(self) -> RLModuleSpec:
        return RLModuleSpec(module_class=OsiTorchRLModule)

    def get_default_learner_class(self) -> type:
        """ESCP's: the `OSI` algorithm swaps it for OSI's when built (`osi_fast_path`), and
        `with_asor` finds ESCP's ASOR Learner for it, which OSI swaps for `AsorOsiTorchLearner`."""
        return EscpTorchLearner

    def validate(self) -> None:
        super().validate()
        OsiSettings.from_dict(self.osi_settings)


def osi_fast_path(config: Any) -> Any:
    """ESCP's run-time wiring (`escp_fast_path`) with OSI's window length and Learner: ESCP's
    Learner becomes OSI's, and with_asor's ESCP Learner OSI's with ASOR (`asor.py`)."""
    s = OsiSettings.from_dict(getattr(config, "osi_settings", None))
    config = config.copy(copy_frozen=False)
    config.escp_settings = {**config.escp_settings, "history_len": s.history_len}
    spec = compat.user_rl_module_spec(config)
    if isinstance(spec, MultiRLModuleSpec):  # with_asor's: the policy's module is OSI's
        for sub in spec.rl_module_specs.values():
            if not sub.learner_only and sub.module_class is None:
                sub.module_class = OsiTorchRLModule
    config = escp_fast_path(config)
    learner = compat.user_learner_class(config)
    if learner is None or learner is EscpTorchLearner:
        config.learners(learner_class=OsiTorchLearner)
    elif isinstance(learner, type) and not issubclass(learner, OsiLearnerMixin):
        config.learners(learner_class=with_osi_losses(learner))  # with_asor's ESCP Learner
    return config


_WITH_OSI: dict[type, type] = {}


def with_osi_losses(escp_learner: type) -> type:
    """A subclass of `escp_learner` (an ESCP Learner of another layer, e.g. with_asor's) with
    OSI's losses mixed in first: `Osi<name>`, made once per class. Ray and RLlib checkpoints
    pickle it by value (cloudpickle), as any class made at run time."""
    if escp_learner not in _WITH_OSI:
        name = "Osi" + escp_learner.__name__
        doc = f"{escp_learner.__name__} with OSI's losses in place of RMDM (osi/learner.py)."
        _WITH_OSI[escp_learner] = type(name, (OsiLearnerMixin, escp_learner), {"__doc__": doc})
    return _WITH_OSI[escp_learner]


class OSI(ESCP):
    """ESCP's algorithm with OSI's replay buffer (true parameters per step), module and Learner."""

    def __init__(self, config: Any = None, *args: Any, **kwargs: Any) -> None:
        if isinstance(config, dict):
            config = self.get_default_config().update_from_dict(config)
        if config is not None:
            config = osi_fast_path(config)
        super().__init__(config, *args, **kwargs)

    @classmethod
    def get_default_config(cls) -> OsiConfig:
        return OsiConfig()

    def setup(self, config: Any) -> None:
        super().setup(config)
        rb = self.config.replay_buffer_config or {}
        self.local_replay_buffer = OsiReplayBuffer(
            capacity=int(rb.get("capacity", 1_000_000)),
            history_len=OsiSettings.from_dict(self.config.osi_settings).history_len,
            seed=rb.get("seed", self.config.seed),
        )
