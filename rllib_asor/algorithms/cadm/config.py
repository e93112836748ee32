"""`CadmConfig` / `CaDM`: CaDM's model-free variant as an RLlib algorithm, on ESCP's machinery.

    from rllib_asor.algorithms.cadm.config import CadmConfig
    config = (CadmConfig()
              .environment("rllib_asor/Walker2dShift-v0", env_config={"num_tasks": 40})
              .cadm(history_len=10))
    algo = config.build_algo()                         # SAC + CaDM context
    algo = rllib_asor.with_asor(config).build_algo()   # with ASOR

An `EscpConfig` (ESCP's SAC defaults, the fast off-policy path, the window connector) whose
module is `CadmTorchRLModule` and whose Learner gets CaDM's loss; `.cadm(...)` sets
`CadmSettings`. The env needs `info["dynamics_id"]` only as ESCP's replay reads it (any int).
"""

from __future__ import annotations

from typing import Any

from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
from ray.rllib.core.rl_module.rl_module import RLModuleSpec

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.cadm.learner import CadmLearnerMixin, CadmTorchLearner
from rllib_asor.algorithms.cadm.module import CADM_KEY, CadmTorchRLModule
from rllib_asor.algorithms.cadm.settings import CadmSettings
from rllib_asor.algorithms.escp.config import ESCP, EscpConfig, escp_fast_path
from rllib_asor.algorithms.escp.learner import EscpTorchLearner
from rllib_asor.algorithms.escp.module import ESCP_KEY
from rllib_asor.algorithms.escp.settings import EscpSettings


class CadmConfig(EscpConfig):
    """`EscpConfig` with CaDM's module, loss and settings (`.cadm(...)`, `CadmSettings`)."""

    def __init__(self, algo_class: type | None = None) -> None:
        super().__init__(algo_class=algo_class or CaDM)
        self.cadm_settings: dict[str, Any] = CadmSettings().to_dict()

    def cadm(self, **settings: Any) -> CadmConfig:
        """Set CaDM's settings (fields of `CadmSettings`); ValueError names a bad key/value."""
        self.cadm_settings = CadmSettings.from_dict({**self.cadm_settings, **settings}).to_dict()
        return self

    @property
    def _model_config_auto_includes(self) -> dict[str, Any]:
        s = CadmSettings.from_dict(self.cadm_settings)
        escp = EscpSettings.from_dict(
            {
                **self.escp_settings,
                "context_dim": s.context_dim,
                "history_len": s.history_len,
                "context_noise": 0.0,
                "encoder_lr": s.model_lr,
                "target_entropy_ratio": s.target_entropy_ratio,
            }
        )
        return super()._model_config_auto_includes | {
            ESCP_KEY: escp.model_dump(),
            CADM_KEY: s.to_dict(),
        }

    def get_default_rl_module_spec(self) -> RLModuleSpec:
        return RLModuleSpec(module_class=CadmTorchRLModule)

    def get_default_learner_class(self) -> type:
        """ESCP's: the `CaDM` algorithm swaps it for CaDM's when built (`cadm_fast_path`), and
        `with_asor` finds ESCP's ASOR Learner for it, which CaDM gives CaDM's loss."""
        return EscpTorchLearner

    def validate(self) -> None:
        super().validate()
        CadmSettings.from_dict(self.cadm_settings)


def cadm_fast_path(config: Any) -> Any:
    """ESCP's run-time wiring (`escp_fast_path`) with CaDM's window length, module and Learner."""
    s = CadmSettings.from_dict(getattr(config, "cadm_settings", None))
    config = config.copy(copy_frozen=False)
    config.escp_settings = {**config.escp_settings, "history_len": s.history_len}
    spec = compat.user_rl_module_spec(config)
    if isinstance(spec, MultiRLModuleSpec):  # with_asor's: the policy's module is CaDM's
        for sub in spec.rl_module_specs.values():
            if not sub.learner_only and sub.module_class is None:
                sub.module_class = CadmTorchRLModule
    config = escp_fast_path(config)
    learner = compat.user_learner_class(config)
    if learner is None or learner is EscpTorchLearner:
        config.learners(learner_class=CadmTorchLearner)
    elif isinstance(learner, type) and not issubclass(learner, CadmLearnerMixin):
        config.learners(learner_class=with_cadm_loss(learner))  # with_asor's ESCP Learner
    return config


_WITH_CADM: dict[type, type] = {}


def with_cadm_loss(escp_learner: type) -> type:
    """A subclass of `escp_learner` (e.g. with_asor's ESCP Learner) with CaDM's loss mixed in
    first: `Cadm<name>`, made once per class (pickled by value, as any class made at run
    time)."""
    if escp_learner not in _WITH_CADM:
        name = "Cadm" + escp_learner.__name__
        doc = f"{escp_learner.__name__} with CaDM's loss in place of RMDM (cadm/learner.py)."
        _WITH_CADM[escp_learner] = type(name, (CadmLearnerMixin, escp_learner), {"__doc__": doc})
    return _WITH_CADM[escp_learner]


class CaDM(ESCP):
    """ESCP's algorithm with CaDM's module and Learner (module docstring)."""

    def __init__(self, config: Any = None, *args: Any, **kwargs: Any) -> None:
        if isinstance(config, dict):
            config = self.get_default_config().update_from_dict(config)
        if config is not None:
            config = cadm_fast_path(config)
        super().__init__(config, *args, **kwargs)

    @classmethod
    def get_default_config(cls) -> CadmConfig:
        return CadmConfig()
