"""The fast off-policy path for SAC and CQL: what it changes and why.

Profiled on Hopper (one local env, 256x256 networks, batch 256, one gradient step per env step;
docs/results.md, "Fast experiments: SAC speed"), a stock RLlib 2.60 SAC gradient step cost
~160 ms where Stable-Baselines3 spends ~18 ms on a whole env step + update. The time went to:

1. **The critic network.** For Box actions RLlib's `SACCatalog` builds each Q network as a
   multi-stream encoder: an obs MLP (obs→256→256), an action MLP (act→256→256) and dense
   "fusion" layers (512→256, 768→256, 768→256) before the head: ~5x the multiply-adds of the
   concat MLP (obs⊕act→256→256→1) that SAC papers, SB3 and CleanRL use, ×6 critic passes
   per step (twin, target, policy term). `FastSACCatalog` builds that concat MLP
   (`fcnet_hiddens` sets its layers; the policy network is unchanged).
2. **Replay.** `EpisodeReplayBuffer` slices a one-step episode per sampled transition;
   `rllib_asor.algorithms.sac.replay.FlatReplayBuffer` samples rows of flat arrays instead
   (`replay_buffer_config: {type: EpisodeReplayBuffer, storage: flat}` + `FlatReplayCallback`,
   because RLlib's SAC validation accepts only its own buffer type names).
3. **The learner connector** walks those 256 episodes to build the batch; our Learners
   (`FastSACLearnerMixin`) build the batch from the buffer's columns directly (ASOR's piece
   then runs on that batch).
4. **One env step and one Learner call per gradient step** (RLlib's
   `rollout_fragment_length="auto"` is n_step = 1 for SAC): every gradient step paid for a
   sampling call, a weight sync and a Learner call with its metrics reduction (~5 ms with
   ASOR's modules). The fast path samples `FRAGMENT` steps per training step and gives each
   Learner call `STEPS_PER_CALL` x batch rows, on which it runs `STEPS_PER_CALL` gradient
   steps of the user's batch size, each followed by its Polyak target update. The
   update-to-data ratio (rows replayed per env step, `training_intensity`) is unchanged; the
   acting policy is at most `FRAGMENT` updates old (SB3's `train_freq`), and ASOR's
   discriminator/proxy work (V(s), partition, bonus) runs once per Learner call on all its
   rows, with the critics of the call's start.

`fast_off_policy(config)` switches all of it on for a SAC or CQL config; `FastSACConfig` /
`run: FastSAC` (rllib_asor/algorithms/sac/config.py) is SAC with it, and `rllib train` puts a
`run: SAC` or `run: CQL` file on it unless `learner_config_dict["fast_off_policy"]` is False.
`with_asor` never does: it keeps whichever path its config is on. Everything is a regular
RLlib extension point (RLModule/catalog class, replay buffer class, Learner class), so
checkpoints, Tune and remote Learners work as before.
"""

from __future__ import annotations

import logging
from typing import Any

import gymnasium as gym
import torch
from ray.rllib.algorithms.cql.torch.default_cql_torch_rl_module import DefaultCQLTorchRLModule
from ray.rllib.algorithms.sac.sac_catalog import SACCatalog
from ray.rllib.algorithms.sac.sac_learner import ACTION_DIST_INPUTS_NEXT, QF_PREDS, QF_TWIN_PREDS
from ray.rllib.algorithms.sac.torch.default_sac_torch_rl_module import DefaultSACTorchRLModule
from ray.rllib.callbacks.callbacks import RLlibCallback
from ray.rllib.core.columns import Columns
from ray.rllib.core.distribution.torch.torch_distribution import (
    TorchDeterministic,
    TorchSquashedGaussian,
)
from ray.rllib.core.models.base import ENCODER_OUT
from ray.rllib.core.models.configs import MLPEncoderConfig
from ray.rllib.core.models.torch.encoder import TorchMLPEncoder
from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
from ray.rllib.core.rl_module.rl_module import RLModule, RLModuleSpec

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.sac.replay import MINIBATCH_KEY
from rllib_asor.evaluation.rollout import deterministic_sample

logger = logging.getLogger(__name__)

FRAGMENT = 16
"""Env steps per env runner and training step on the fast path (RLlib's SAC default: 1)."""
STEPS_PER_CALL = 16
"""Gradient steps per Learner call on the fast path: the Learner gets STEPS_PER_CALL x batch
replayed rows, runs ASOR's piece once on them and steps on minibatches of the user's batch
size (`learner_config_dict[MINIBATCH_KEY]`, replay.py), with a Polyak target update after each."""
FAST_KEY = "fast_off_policy"
"""`learner_config_dict` key: True once `fast_off_policy` ran, False opts a `run: SAC` file out."""
FLAT_STORAGE = "flat"
"""`replay_buffer_config["storage"]` that makes `FlatReplayCallback` install `FlatReplayBuffer`
(RLlib's SAC validation accepts only its own buffer type names, so the type stays
`EpisodeReplayBuffer`, which ignores the extra key)."""


class FlatReplayCallback(RLlibCallback):
    """Swaps the Algorithm's fresh `EpisodeReplayBuffer` for a `FlatReplayBuffer` of the same
    capacity when `replay_buffer_config["storage"] == "flat"` (before any sample is stored;
    a checkpoint restore then fills the new buffer)."""

    def on_algorithm_init(self, *, algorithm: Any, **kwargs: Any) -> None:
        install_flat_buffer(algorithm)


def install_flat_buffer(algorithm: Any) -> bool:
    """Install `FlatReplayBuffer` on `algorithm` if its config asks for it; True if done."""
    from ray.rllib.utils.replay_buffers.episode_replay_buffer import EpisodeReplayBuffer

    from rllib_asor.algorithms.sac.replay import FlatReplayBuffer

    rb = algorithm.config.replay_buffer_config or {}
    current = getattr(algorithm, "local_replay_buffer", None)
    if rb.get("storage") != FLAT_STORAGE or type(current) is not EpisodeReplayBuffer:
        return False
    algorithm.local_replay_buffer = FlatReplayBuffer(
        capacity=int(rb.get("capacity", 1_000_000)), seed=rb.get("seed")
    )
    return True


class ConcatQEncoder(TorchMLPEncoder):
    """Q encoder of the SAC papers / SB3 / CleanRL: one MLP on [obs, action]."""

    def _forward(self, inputs: dict, **kwargs: Any) -> dict:
        obs = inputs[Columns.OBS]
        x = torch.cat([obs.reshape(obs.shape[0], -1), inputs[Columns.ACTIONS]], dim=-1)
        return {ENCODER_OUT: self.net(x)}


class SquashedGaussian(TorchSquashedGaussian):
    """RLlib's squashed Gaussian whose deterministic action is the squashed mean tanh(μ), the
    mode of what it samples (RLlib 2.60 returns μ before the tanh: greedy evaluation and V(s)
    then used actions the policy never takes)."""

    def to_deterministic(self) -> TorchDeterministic:
        return TorchDeterministic(loc=deterministic_sample(self))


class FastSACCatalog(SACCatalog):
    """`SACCatalog` whose continuous-action Q networks are concat MLPs (`ConcatQEncoder`) and
    whose squashed Gaussian's deterministic action is tanh(μ) (`SquashedGaussian`).

    Falls back to RLlib's multi-stream Q encoder for non-flat (image, dict) observations."""

    def get_action_dist_cls(self, framework: str) -> Any:
        cls = super().get_action_dist_cls(framework)
        return SquashedGaussian if cls is TorchSquashedGaussian else cls

    def _build_qf_encoder_continuous(self, framework: str) -> Any:
        obs_space, enc = self.observation_space, compat.catalog_encoder_config(self)
        if not (
            framework == "torch"
            and isinstance(obs_space, gym.spaces.Box)
            and len(obs_space.shape) == 1
            and type(enc) is MLPEncoderConfig
        ):
            return super()._build_qf_encoder_continuous(framework)
        act_dim = int(self.action_space.shape[0])
        self.qf_encoder_config = MLPEncoderConfig(
            input_dims=[int(obs_space.shape[0]) + act_dim],
            hidden_layer_dims=enc.hidden_layer_dims,
            hidden_layer_activation=enc.hidden_layer_activation,
            hidden_layer_weights_initializer=enc.hidden_layer_weights_initializer,
            hidden_layer_weights_initializer_config=enc.hidden_layer_weights_initializer_config,
            hidden_layer_bias_initializer=enc.hidden_layer_bias_initializer,
            hidden_layer_bias_initializer_config=enc.hidden_layer_bias_initializer_config,
            output_layer_dim=enc.output_layer_dim,
            output_layer_activation=enc.output_layer_activation,
        )
        return ConcatQEncoder(self.qf_encoder_config)


class TrainModeOnceMixin:
    """`forward_train` without TorchRLModule's `self.train()` walk over every submodule when
    the module is already in training mode (RLlib's `forward_inference`/`forward_exploration`
    restore it with `train()` after their `eval()`): ~3 % of a fast SAC gradient step."""

    def forward_train(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        if not self.training:  # type: ignore[attr-defined]
            self.train()  # type: ignore[attr-defined]
        return RLModule.forward_train(self, batch, **kwargs)  # type: ignore[arg-type]


class FastSACTorchRLModule(TrainModeOnceMixin, DefaultSACTorchRLModule):
    """RLlib's SAC module with `FastSACCatalog` (concat-MLP critics) unless told otherwise.

    Its continuous-action `_forward_train` computes what RLlib's does, with the same random
    draws in the same order, but runs the next-state policy pass without autograd (RLlib
    builds and then detaches it) and keeps the list of critic parameters it freezes for the
    policy term instead of rebuilding it every step."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs["catalog_class"] = kwargs.get("catalog_class") or FastSACCatalog
        super().__init__(*args, **kwargs)

    @property
    def disjoint_optimizer_losses(self) -> bool:
        """Each optimizer's loss reaches only its own parameters (Box actions: this module's
        forward and RLlib's SAC loss), so one backward pass of their sum gives every
        parameter its own loss's gradient (`FastSACLearnerMixin.compute_gradients`)."""
        return isinstance(self.action_space, gym.spaces.Box) and not self.inference_only

    def _critic_params(self) -> list[torch.nn.Parameter]:
        params = self.__dict__.get("_fast_critic_params")
        if params is None:
            nets = [self.qf, self.qf_encoder]
            if self.twin_q:
                nets += [self.qf_twin, self.qf_twin_encoder]
            params = [p for net in nets for p in net.parameters()]
            self.__dict__["_fast_critic_params"] = params  # not a submodule: no state_dict entry
        return params

    def _forward_train_continuous(self, batch: dict[str, Any]) -> dict[str, Any]:
        obs, next_obs = batch[Columns.OBS], batch[Columns.NEXT_OBS]
        out: dict[str, Any] = {}
        logits = self.pi(self.pi_encoder({Columns.OBS: obs})[ENCODER_OUT])
        with torch.no_grad():
            logits_next = self.pi(self.pi_encoder({Columns.OBS: next_obs})[ENCODER_OUT])
        taken = {Columns.OBS: obs, Columns.ACTIONS: batch[Columns.ACTIONS]}
        out[QF_PREDS] = self.qf(self.qf_encoder(taken)[ENCODER_OUT]).squeeze(-1)
        if self.twin_q:
            out[QF_TWIN_PREDS] = self.qf_twin(self.qf_twin_encoder(taken)[ENCODER_OUT]).squeeze(-1)
        out[Columns.ACTION_DIST_INPUTS] = logits
        out[ACTION_DIST_INPUTS_NEXT] = logits_next
        dist_cls = self.get_train_action_dist_cls()
        actions, out["logp_resampled"] = dist_cls.from_logits(logits).rsample_and_logp()
        with torch.no_grad():
            next_actions, out["logp_next_resampled"] = dist_cls.from_logits(
                logits_next
            ).sample_and_logp()
        params = self._critic_params()
        for p in params:  # Q's gradient reaches π only (as RLlib's module)
            p.requires_grad_(False)
        try:
            out["q_curr"] = self.compute_q_values({Columns.OBS: obs, Columns.ACTIONS: actions})
        finally:
            for p in params:
                p.requires_grad_(True)
        with torch.no_grad():
            out["q_target_next"] = self.forward_target(
                {Columns.OBS: next_obs, Columns.ACTIONS: next_actions}
            )
        return out


class FastCQLTorchRLModule(DefaultCQLTorchRLModule):
    """RLlib's CQL module with `FastSACCatalog` (concat-MLP critics)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs["catalog_class"] = kwargs.get("catalog_class") or FastSACCatalog
        super().__init__(*args, **kwargs)


_STOCK_MODULES = (None, DefaultSACTorchRLModule, DefaultCQLTorchRLModule)


def _fast_module_class(algo: str) -> type:
    return FastCQLTorchRLModule if algo == "CQL" else FastSACTorchRLModule


def _set_module_class(config: Any, algo: str) -> None:
    """Give every policy spec that uses RLlib's default SAC/CQL module our fast module."""
    fast = _fast_module_class(algo)
    spec = compat.user_rl_module_spec(config)
    if spec is None:
        config.rl_module(rl_module_spec=RLModuleSpec(module_class=fast))
    elif isinstance(spec, MultiRLModuleSpec):
        for sub in spec.rl_module_specs.values():
            if sub.module_class in _STOCK_MODULES and not sub.learner_only:
                sub.module_class = fast
    elif isinstance(spec, RLModuleSpec) and spec.module_class in _STOCK_MODULES:
        spec.module_class = fast


def fast_off_policy(config: Any, enabled: bool = True) -> Any:
    """Return a copy of a SAC or CQL `config` on the fast path (module docstring).

    Single-agent SAC with a uniform `EpisodeReplayBuffer` and n_step 1 gets all four parts;
    other SAC settings (prioritized replay, n-step, multi-agent) keep RLlib's buffer and
    connector path but still get the concat-MLP critics. CQL gets the critics (its batches
    come from Ray Data). `enabled=False` only records the opt-out (a `run: SAC` file's).
    """
    # "SAC" or "CQL" for those algorithms or a subclass of one (`FastSAC`)
    mro = getattr(config.algo_class, "__mro__", ())
    algo = next((c.__name__ for c in mro if c.__name__ in ("SAC", "CQL")), "")
    config = config.copy(copy_frozen=False)
    lcd = dict(config.learner_config_dict or {})
    if enabled and lcd.get(FAST_KEY) is True:
        return config  # already on the fast path (e.g. a restored trial)
    if not enabled:
        lcd[FAST_KEY] = False
        config.learners(learner_config_dict=lcd)
        return config
    if algo not in ("SAC", "CQL"):
        raise ValueError(f"fast_off_policy supports SAC and CQL, got {algo or type(config)}")
    lcd[FAST_KEY] = True
    config.learners(learner_config_dict=lcd)
    _set_module_class(config, algo)
    if algo == "SAC":
        _fast_replay(config)
    return config


def _fast_replay(config: Any) -> None:
    from rllib_asor.algorithms.sac.learner import FastSACTorchLearner

    rb = dict(config.replay_buffer_config or {})
    n_step = config.n_step
    if config.is_multi_agent or rb.get("type") != "EpisodeReplayBuffer" or n_step != 1:
        logger.info(
            "fast_off_policy: keeping RLlib's replay path (type=%r, n_step=%r, multi-agent=%s)",
            rb.get("type"),
            n_step,
            config.is_multi_agent,
        )
        return
    rb["storage"] = FLAT_STORAGE
    if config.seed is not None:
        rb.setdefault("seed", config.seed)
    config.training(replay_buffer_config=rb)
    from rllib_asor.algorithms.common.callbacks import add_callbacks

    add_callbacks(config, FlatReplayCallback)
    if compat.user_learner_class(config) is None:
        config.learners(learner_class=FastSACTorchLearner)
    if config.rollout_fragment_length != "auto":
        return  # the user's own sampling/update rhythm: one gradient step per Learner call
    # Keep the update-to-data ratio while sampling FRAGMENT steps per env (runner) and doing
    # STEPS_PER_CALL gradient steps of the user's batch per Learner call. RLlib's ratio is
    # training_intensity = rows replayed per sampled env step; without one, RLlib's "auto"
    # (fragment n_step = 1) meant one update of the total batch per such sample.
    batch = config.train_batch_size_per_learner
    if not config.training_intensity:
        envs = config.num_envs_per_env_runner * max(config.num_env_runners + 1, 1)
        config.training(training_intensity=config.total_train_batch_size / envs)
    lcd = dict(config.learner_config_dict or {})
    lcd[MINIBATCH_KEY] = batch
    config.learners(learner_config_dict=lcd)
    config.training(train_batch_size_per_learner=batch * STEPS_PER_CALL)
    config.env_runners(rollout_fragment_length=FRAGMENT)
