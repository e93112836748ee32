"""`FastSACConfig` / `FastSAC`: RLlib's SAC on the fast off-policy path, as a choice of its own.

    from rllib_asor import FastSACConfig, with_asor
    config = FastSACConfig().environment("Pendulum-v1")
    baseline = config.build_algo()                 # SAC on the fast path
    treatment = with_asor(config).build_algo()     # the same SAC, plus ASOR

`with_asor` never changes the base algorithm: `with_asor(SACConfig())` is RLlib's stock SAC
plus ASOR, `with_asor(FastSACConfig())` the fast path plus ASOR. In YAML: `run: FastSAC`.

The fast path (rllib_asor/algorithms/sac/fast.py): concat-MLP critics (`FastSACTorchRLModule`),
a flat replay buffer, batches built from its columns (`FastSACTorchLearner`), `FRAGMENT` env
steps per runner and `STEPS_PER_CALL` gradient steps of the user's batch per Learner call at
the user's update-to-data ratio. The sampling rhythm depends on settings made after the config
is created (batch size, env runners), so `FastSAC` applies `fast_off_policy` when it is built;
`on_fast_path()` shows the config it then runs.
"""

from __future__ import annotations

from typing import Any

from ray.rllib.algorithms.sac.sac import SAC, SACConfig
from ray.rllib.core.rl_module.rl_module import RLModuleSpec

from rllib_asor.algorithms.sac.fast import FastSACTorchRLModule, fast_off_policy
from rllib_asor.algorithms.sac.learner import FastSACTorchLearner


class FastSACConfig(SACConfig):
    """RLlib's `SACConfig` whose default module, Learner and replay are the fast path's
    (uniform replay by default; prioritized or n-step replay keeps RLlib's buffer, as
    `fast_off_policy` says)."""

    def __init__(self, algo_class: type | None = None) -> None:
        super().__init__(algo_class=algo_class or FastSAC)
        # uniform replay, which the flat buffer gives (RLlib's SAC default is prioritized)
        self.replay_buffer_config = {"type": "EpisodeReplayBuffer", "capacity": 1_000_000}

    def get_default_rl_module_spec(self) -> RLModuleSpec:
        return RLModuleSpec(module_class=FastSACTorchRLModule)

    def get_default_learner_class(self) -> type:
        return FastSACTorchLearner

    def on_fast_path(self) -> SACConfig:
        """A copy with every fast-path setting applied, as `FastSAC` runs it (idempotent)."""
        return fast_off_policy(self)


class FastSAC(SAC):
    """RLlib's SAC algorithm built from a `FastSACConfig` on the fast off-policy path."""

    def __init__(self, config: Any = None, *args: Any, **kwargs: Any) -> None:
        if isinstance(config, dict):
            config = self.get_default_config().update_from_dict(config)
        if config is not None:
            config = fast_off_policy(config)
        super().__init__(config, *args, **kwargs)

    @classmethod
    def get_default_config(cls) -> FastSACConfig:
        return FastSACConfig()
