"""`EscpConfig`: ESCP as an RLlib algorithm (a `FastSACConfig` with ESCP's settings and defaults).

    from rllib_asor import EscpConfig, with_asor
    config = (
        EscpConfig()
        .environment("rllib_asor/Walker2dShift-v0", env_config={"num_tasks": 40})
        .escp(history_len=16, context_dim=2)
    )
    algo = config.build_algo()                      # ESCP
    algo = with_asor(config).build_algo()           # ESCP + ASOR (the paper's Algorithm 1)

SAC defaults changed to ESCP's (`parameter/Parameter.py`): actor lr 3e-4 (`learning_rate`),
critic lr 1e-3 (`value_learning_rate`), temperature lr 1e-2 and initial α 0.2
(`SAC.__init__`: `alpha_optimizer`, `sac_alpha`), τ 0.005 (`sac_tau` 0.995), batch 256
(`sac_mini_batch_size`), learning after 20,000 steps (`start_train_num`), π/Q 128-64 with
LeakyReLU (`up_hidden_size`, `value_hidden_size`), one gradient step per env step. ESCP's
4,000 uniformly random first actions (`random_num`) have no RLlib counterpart (RLlib samples
the initial policy).

Needs an env reporting `info["dynamics_id"]` (the training task), Box actions and flat Box
observations; single-agent, n_step 1, uniform replay. ESCP builds on the fast off-policy path
(`FastSACConfig`, for both arms of an ESCP vs ESCP+ASOR comparison): the `ESCP` algorithm
applies `escp_fast_path` when it is built (`on_fast_path()` shows the result): its replay
buffer, the window connector, and `FRAGMENT` env steps / `STEPS_PER_CALL` gradient steps per
call.
"""

from __future__ import annotations

from typing import Any

from ray.rllib.algorithms.sac.sac import SAC, SACConfig
from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
from ray.rllib.core.rl_module.rl_module import RLModuleSpec

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.escp.connector import EscpEnvToModule
from rllib_asor.algorithms.escp.learner import EscpLearnerMixin, EscpTorchLearner
from rllib_asor.algorithms.escp.module import ESCP_KEY, EscpTorchRLModule
from rllib_asor.algorithms.escp.replay import EscpReplayBuffer
from rllib_asor.algorithms.escp.settings import EscpSettings
from rllib_asor.algorithms.sac.config import FastSACConfig
from rllib_asor.algorithms.sac.fast import FAST_KEY, FRAGMENT, STEPS_PER_CALL
from rllib_asor.algorithms.sac.replay import MINIBATCH_KEY


class EscpConfig(FastSACConfig):
    """`FastSACConfig` (RLlib's `SACConfig` on the fast path) plus ESCP's settings
    (`.escp(...)`, `EscpSettings`)."""

    def __init__(self, algo_class: type | None = None) -> None:
        super().__init__(algo_class=algo_class or ESCP)
        self.actor_lr = 3e-4
        self.critic_lr = 1e-3
        self.alpha_lr = 1e-2
        self.initial_alpha = 0.2
        self.tau = 5e-3
        self.twin_q = True
        self.n_step = 1
        self.train_batch_size_per_learner = 256
        self.num_steps_sampled_before_learning_starts = 20_000
        self.replay_buffer_config = {"type": "EpisodeReplayBuffer", "capacity": 1_000_000}
        self.rl_module(model_config={"fcnet_hiddens": [128, 64], "fcnet_activation": "leaky_relu"})
        self.escp_settings: dict[str, Any] = EscpSettings().to_dict()
        # With several Learners (DDP): the encoder learns from RMDM alone, which is off until
        # enough tasks are in the replay (and per batch), so it legitimately has no gradient
        # in those updates; DDP must be told (tests/cluster/test_many_learners.py).
        self.torch_ddp_kwargs = {"find_unused_parameters": True}

    def escp(self, **settings: Any) -> EscpConfig:
        """Set ESCP's settings (fields of `EscpSettings`); ValueError names a bad key/value."""
        merged = {**self.escp_settings, **settings}
        self.escp_settings = EscpSettings.from_dict(merged).to_dict()
        return self

    @property
    def _model_config_auto_includes(self) -> dict[str, Any]:
        return super()._model_config_auto_includes | {ESCP_KEY: dict(self.escp_settings)}

    def get_default_rl_module_spec(self) -> RLModuleSpec:
        return RLModuleSpec(module_class=EscpTorchRLModule)

    def get_default_learner_class(self) -> type:
        return EscpTorchLearner

    def on_fast_path(self) -> SACConfig:
        """A copy with what the `ESCP` algorithm applies when built (`escp_fast_path`)."""
        return escp_fast_path(self)

    def validate(self) -> None:
        super().validate()
        EscpSettings.from_dict(self.escp_settings)
        check_escp_config(self)


def check_escp_config(config: SACConfig) -> None:
    """ESCP's limits, as ValueErrors naming the key, the value and what is allowed."""
    if config.is_multi_agent:
        raise ValueError("ESCP is single-agent; multi-agent configs are not supported")
    if config.n_step not in (1, None):
        raise ValueError(f"n_step={config.n_step!r} is not allowed for ESCP; expected 1")
    rb_type = (config.replay_buffer_config or {}).get("type")
    if rb_type != "EpisodeReplayBuffer":
        raise ValueError(
            f"replay_buffer_config.type={rb_type!r} is not allowed for ESCP; expected "
            "'EpisodeReplayBuffer' (uniform replay; ESCP keeps its own flat buffer)"
        )
    learner = compat.user_learner_class(config)
    if learner is not None and not (
        isinstance(learner, type) and issubclass(learner, EscpLearnerMixin)
    ):
        raise ValueError(
            f"learner_class={getattr(learner, '__name__', learner)!r} is not allowed for ESCP; "
            "expected a subclass of EscpLearnerMixin (EscpTorchLearner, or with_asor's)"
        )


def escp_fast_path(config: SACConfig) -> SACConfig:
    """A copy of an ESCP config with what ESCP needs at run time (idempotent):
    the window connector, a lookback of H steps, and the fast path's sampling rhythm
    (FRAGMENT env steps per runner, STEPS_PER_CALL gradient steps of the user's batch per
    Learner call, the update-to-data ratio kept; rllib_asor/algorithms/sac/fast.py)."""
    config = config.copy(copy_frozen=False)
    lcd = dict(config.learner_config_dict or {})
    if lcd.get(FAST_KEY) is True:
        return config
    check_escp_config(config)
    settings = EscpSettings.from_dict(getattr(config, "escp_settings", None))
    h = settings.history_len
    config.env_runners(
        env_to_module_connector=EscpEnvToModule(
            h, user=compat.user_env_to_module_connector(config)
        ),
        episode_lookback_horizon=max(int(config.episode_lookback_horizon or 1), h),
    )
    if compat.user_learner_class(config) is None:
        config.learners(learner_class=EscpTorchLearner)
    _policy_module_class(config)
    lcd[FAST_KEY] = True
    if config.rollout_fragment_length == "auto":
        batch = config.train_batch_size_per_learner
        if not config.training_intensity:
            envs = config.num_envs_per_env_runner * max(config.num_env_runners + 1, 1)
            config.training(training_intensity=config.total_train_batch_size / envs)
        lcd[MINIBATCH_KEY] = batch
        config.training(train_batch_size_per_learner=batch * STEPS_PER_CALL)
        config.env_runners(rollout_fragment_length=FRAGMENT)
    config.learners(learner_config_dict=lcd)
    return config


def _policy_module_class(config: SACConfig) -> None:
    spec = compat.user_rl_module_spec(config)
    if isinstance(spec, MultiRLModuleSpec):
        for sub in spec.rl_module_specs.values():
            if not sub.learner_only and sub.module_class is None:
                sub.module_class = EscpTorchRLModule


class ESCP(SAC):
    """SAC's algorithm with ESCP's replay buffer, Learner and module (module docstring)."""

    def __init__(self, config: Any = None, *args: Any, **kwargs: Any) -> None:
        if isinstance(config, dict):
            config = self.get_default_config().update_from_dict(config)
        if config is not None:
            config = escp_fast_path(config)
        super().__init__(config, *args, **kwargs)

    @classmethod
    def get_default_config(cls) -> EscpConfig:
        return EscpConfig()

    def setup(self, config: Any) -> None:
        super().setup(config)
        rb = self.config.replay_buffer_config or {}
        settings = EscpSettings.from_dict(getattr(self.config, "escp_settings", None))
        self.local_replay_buffer = EscpReplayBuffer(
            capacity=int(rb.get("capacity", 1_000_000)),
            history_len=settings.history_len,
            seed=rb.get("seed", self.config.seed),
        )
