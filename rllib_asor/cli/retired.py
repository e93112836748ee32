"""Config keys of old RLlib files that the new API stack retired: each goes to its new home, or is
dropped with a warning that says it has no effect now (docs/cli.md has the table).

`translate(key, value, into)` handles one retired key and returns True; False for other keys.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from rllib_asor.cli.errors import UsageError

FRAMEWORK_NOTE = (
    "the algorithm is the same, but its numbers will differ from a tf run (other "
    "initialisation and numerics)"
)

DROPPED_KEYS: dict[str, str] = {
    "enable_connectors": "the new API stack always uses connectors",
    "soft_horizon": "episodes end where the env (or its episode limit) ends them",
    "no_done_at_end": "the new API stack keeps the env's terminated/truncated flags",
    "num_accs": "it tuned an old multi-GPU optimizer",
    "simple_optimizer": "the new API stack has one Learner path",
    "eager_tracing": "it is a tf setting",
    "_disable_preprocessor_api": "the new API stack has no preprocessors",
    "worker_side_prioritization": "the replay buffer lives on the driver",
    "num_gpus": "use num_gpus_per_learner (the Learners own the GPUs now)",
    "_fake_gpus": "use num_gpus_per_learner",
}
"""Keys with no new-stack meaning: dropped, with why."""

OPTIMIZATION_KEYS = {
    "actor_learning_rate": "actor_lr",
    "critic_learning_rate": "critic_lr",
    "entropy_learning_rate": "alpha_lr",
}
"""SAC's old `optimization: {...}` block -> the new config keys."""

SAC_MODEL_KEYS = ("Q_model", "policy_model", "q_model_config", "policy_model_config")
SAC_MODEL_SETTINGS = {"fcnet_hiddens": "fcnet_hiddens", "fcnet_activation": "fcnet_activation"}
"""Old SAC per-network model blocks: their hidden layers and activation -> `model_config`."""

REPLAY_TYPES = {
    "MultiAgentPrioritizedReplayBuffer": "PrioritizedEpisodeReplayBuffer",
    "PrioritizedReplayBuffer": "PrioritizedEpisodeReplayBuffer",
    "MultiAgentReplayBuffer": "EpisodeReplayBuffer",
    "ReplayBuffer": "EpisodeReplayBuffer",
}
"""Old replay buffer class names -> the new stack's episode buffers."""

REPLAY_KEYS = {"prioritized_replay_alpha": "alpha", "prioritized_replay_beta": "beta"}
REPLAY_TOP_KEYS = {"buffer_size": "capacity", **REPLAY_KEYS}
"""Old top-level replay keys -> `replay_buffer_config` keys."""
REPLAY_DROPPED = (
    "prioritized_replay_eps",
    "replay_sequence_length",
    "replay_burn_in",
    "replay_zero_init_states",
    "replay_mode",
    "storage_unit",
    "worker_side_prioritization",
    "replay_batch_size",
)
REPLAY_LEARNING_STARTS = ("learning_starts", "min_size_for_sampling")
"""Inside `replay_buffer_config`: when learning starts is a top-level setting now."""

FRAMEWORKS = ("torch", "tf", "tf2", "tfe")
RETIRED_KEYS = (
    "framework",
    "use_pytorch",
    "horizon",
    "optimization",
    "prioritized_replay",
    "replay_buffer_config",
    *DROPPED_KEYS,
    *SAC_MODEL_KEYS,
    *REPLAY_TOP_KEYS,
    *REPLAY_DROPPED,
)


@dataclass
class Into:
    """Where translated settings go: the new config, its model_config and env_config, and the
    warnings (one per translated key)."""

    out: dict[str, Any]
    model_config: dict[str, Any]
    source: str
    prefix: str
    warnings: list[str] = field(default_factory=list)
    env_config: dict[str, Any] = field(default_factory=dict)

    def warn(self, message: str) -> None:
        self.warnings.append(f"{self.source}: {message}")

    def replay(self) -> dict[str, Any]:
        block = self.out.setdefault("replay_buffer_config", {})
        if not isinstance(block, dict):
            raise UsageError(
                f"{block!r} is invalid: allowed a mapping",
                source=self.source,
                key=f"{self.prefix}replay_buffer_config",
            )
        return block


def translate(key: str, value: Any, into: Into) -> bool:
    """Translate one retired `key`; False when `key` is not a retired key."""
    if key == "vtrace" and value is False:
        raise UsageError(
            "vtrace: false is not supported by RLlib 2.60's APPO/IMPALA (V-trace is always on): "
            "remove the key, or use run: PPO for GAE advantages",
            source=into.source,
            key=f"{into.prefix}vtrace",
        )
    if key not in RETIRED_KEYS:
        return False
    if key in ("framework", "use_pytorch"):
        _framework(key, value, into)
    elif key in DROPPED_KEYS:
        into.warn(
            f"legacy key '{key}' dropped: no effect on the new API stack ({DROPPED_KEYS[key]})"
        )
    elif key == "horizon":
        if value is not None:
            into.env_config.setdefault("max_episode_steps", value)
            into.warn(f"legacy key 'horizon: {value}' translated to 'env_config.max_episode_steps'")
    elif key == "optimization":
        _optimization(value, into)
    elif key in SAC_MODEL_KEYS:
        _sac_model(key, value, into)
    elif key == "prioritized_replay":
        kind = "PrioritizedEpisodeReplayBuffer" if value else "EpisodeReplayBuffer"
        into.replay().setdefault("type", kind)
        into.warn(
            f"legacy key 'prioritized_replay: {value}' translated to 'replay_buffer_config.type: {kind}'"
        )
    elif key == "replay_buffer_config":
        _replay_block(value, into)
    elif key in REPLAY_TOP_KEYS:
        into.replay()[REPLAY_TOP_KEYS[key]] = value
        into.warn(f"legacy key '{key}' translated to 'replay_buffer_config.{REPLAY_TOP_KEYS[key]}'")
    else:  # REPLAY_DROPPED at the top level
        into.warn(f"legacy key '{key}' dropped: no effect on the new API stack's replay buffers")
    return True


def _framework(key: str, value: Any, into: Into) -> None:
    if key == "use_pytorch":
        value = "torch" if value else "tf"
    if value not in FRAMEWORKS and value is not None:
        raise UsageError(
            f"framework {value!r} is invalid: allowed {' | '.join(FRAMEWORKS)} (all run as torch)",
            source=into.source,
            key=f"{into.prefix}{key}",
        )
    if value in (None, "torch"):
        if key == "use_pytorch":
            into.warn("legacy key 'use_pytorch: true' dropped: torch is the only framework")
        return
    shown = "use_pytorch: false" if key == "use_pytorch" else f"framework: {value}"
    into.warn(
        f"'{shown}' runs as torch (the only framework of RLlib's new API stack): {FRAMEWORK_NOTE}"
    )


def _optimization(value: Any, into: Into) -> None:
    block = value if isinstance(value, dict) else None
    if block is None or set(block) - set(OPTIMIZATION_KEYS):
        raise UsageError(
            f"{value!r} is invalid: allowed a mapping with {', '.join(OPTIMIZATION_KEYS)}",
            source=into.source,
            key=f"{into.prefix}optimization",
        )
    for old, new in OPTIMIZATION_KEYS.items():
        if old in block:
            into.out.setdefault(new, block[old])
            into.warn(f"legacy key 'optimization.{old}' translated to '{new}'")


def _sac_model(key: str, value: Any, into: Into) -> None:
    block = dict(value) if isinstance(value, dict) else None
    if block is None:
        raise UsageError(
            f"{value!r} is invalid: allowed a mapping of model settings",
            source=into.source,
            key=f"{into.prefix}{key}",
        )
    for old, new in SAC_MODEL_SETTINGS.items():
        if old in block:
            have = into.model_config.setdefault(new, block[old])
            if have != block[old]:
                into.warn(
                    f"'{key}.{old}: {block[old]}' differs from the other network's '{have}': "
                    "the new API stack's SAC uses one model_config for policy and critics; kept "
                    f"'{have}'"
                )
    rest = sorted(set(block) - set(SAC_MODEL_SETTINGS))
    dropped = f" ({', '.join(rest)} dropped: no new-stack meaning)" if rest else ""
    into.warn(
        f"legacy key '{key}' translated to 'model_config' (fcnet_hiddens, fcnet_activation){dropped}"
    )


def _replay_block(value: Any, into: Into) -> None:
    if not isinstance(value, dict):
        raise UsageError(
            f"{value!r} is invalid: allowed a mapping",
            source=into.source,
            key=f"{into.prefix}replay_buffer_config",
        )
    block = into.replay()
    for key, sub in value.items():
        if key == "type" and sub in REPLAY_TYPES:
            block[key] = REPLAY_TYPES[sub]
            into.warn(f"replay buffer type '{sub}' translated to '{REPLAY_TYPES[sub]}'")
        elif key in REPLAY_KEYS:
            block[REPLAY_KEYS[key]] = sub
            into.warn(
                f"'replay_buffer_config.{key}' translated to 'replay_buffer_config.{REPLAY_KEYS[key]}'"
            )
        elif key in REPLAY_LEARNING_STARTS:
            into.out.setdefault("num_steps_sampled_before_learning_starts", sub)
            into.warn(
                f"'replay_buffer_config.{key}' translated to 'num_steps_sampled_before_learning_starts'"
            )
        elif key in REPLAY_DROPPED:
            into.warn(f"'replay_buffer_config.{key}' dropped: no effect on the new API stack")
        else:
            block[key] = sub
