"""Translation of old RLlib config/stop keys to the new API stack, with a warning each."""

from __future__ import annotations

from typing import Any

from rllib_asor.cli import retired
from rllib_asor.cli.errors import Problems, UsageError

# Old config key -> new config key (same value).
RENAMED_CONFIG_KEYS: dict[str, str] = {
    "num_workers": "num_env_runners",
    "num_envs_per_worker": "num_envs_per_env_runner",
    "num_cpus_per_worker": "num_cpus_per_env_runner",
    "num_gpus_per_worker": "num_gpus_per_env_runner",
    "custom_resources_per_worker": "custom_resources_per_env_runner",
    "num_cpus_for_driver": "num_cpus_for_main_process",
    "num_sgd_iter": "num_epochs",
    "sgd_minibatch_size": "minibatch_size",
    "evaluation_num_workers": "evaluation_num_env_runners",
    "recreate_failed_workers": "restart_failed_env_runners",
    "ignore_worker_failures": "ignore_env_runner_failures",
    "metrics_smoothing_episodes": "metrics_num_episodes_for_smoothing",
    "min_iter_time_s": "min_time_s_per_iteration",
    "timesteps_per_iteration": "min_sample_timesteps_per_iteration",
    "learning_starts": "num_steps_sampled_before_learning_starts",
}

# Where one algorithm's own deprecation message sends an old key elsewhere (offline CQL trains
# without sampling: RLlib's cql.py names min_train_timesteps_per_iteration).
RENAMED_CONFIG_KEYS_BY_RUN: dict[str, dict[str, str]] = {
    "CQL": {"timesteps_per_iteration": "min_train_timesteps_per_iteration"},
}

# Old top-level config keys that now live in `model_config` (config.rl_module(model_config=...)).
MODEL_CONFIG_TOPLEVEL_KEYS = ("vf_share_layers",)

# Old result names -> new result names (for `stop`).
RENAMED_STOP_KEYS: dict[str, str] = {
    "episode_reward_mean": "env_runners/episode_return_mean",
    "episode_reward_max": "env_runners/episode_return_max",
    "episode_reward_min": "env_runners/episode_return_min",
    "episode_len_mean": "env_runners/episode_len_mean",
    "sampler_results/episode_reward_mean": "env_runners/episode_return_mean",
    "env_runners/episode_reward_mean": "env_runners/episode_return_mean",
    "evaluation/episode_reward_mean": "evaluation/env_runners/episode_return_mean",
    "evaluation/sampler_results/episode_reward_mean": "evaluation/env_runners/episode_return_mean",
    "timesteps_total": "num_env_steps_sampled_lifetime",
    # the new stack counts agent steps per agent id; one agent's id is `default_agent`
    "agent_timesteps_total": "env_runners/num_agent_steps_sampled_lifetime/default_agent",
    "num_env_steps_sampled": "num_env_steps_sampled_lifetime",
    "num_agent_steps_sampled": "env_runners/num_agent_steps_sampled_lifetime/default_agent",
}

# Old experiment-level keys -> where they go now.
RENAMED_SPEC_KEYS: dict[str, tuple[str, str]] = {
    "checkpoint_freq": ("checkpoint_config", "checkpoint_frequency"),
    "checkpoint_at_end": ("checkpoint_config", "checkpoint_at_end"),
    "keep_checkpoints_num": ("checkpoint_config", "num_to_keep"),
    "checkpoint_score_attr": ("checkpoint_config", "checkpoint_score_attribute"),
    "local_dir": ("", "storage_path"),
}

# Our own class paths in the package's earlier layout -> where they live now (YAML files keep
# working).
MOVED_MODULES: dict[str, str] = {
    "rllib_asor.rllib.learner_speed": "rllib_asor.algorithms.common.learner_speed",
    "rllib_asor.rllib.pipeline": "rllib_asor.algorithms.common.pipeline",
    "rllib_asor.rllib.faults": "rllib_asor.algorithms.common.faults",
    "rllib_asor.rllib.lean_ppo": "rllib_asor.algorithms.ppo.lean",
    "rllib_asor.rllib.overlap": "rllib_asor.algorithms.ppo.overlap",
    "rllib_asor.rllib.fast_sac": "rllib_asor.algorithms.sac.fast",
    "rllib_asor.rllib.replay": "rllib_asor.algorithms.sac.replay",
    "rllib_asor.rllib.offline": "rllib_asor.algorithms.cql.offline",
    "rllib_asor.rllib.race": "rllib_asor.race.config",
    "rllib_asor.rllib.curriculum": "rllib_asor.race.curriculum",
    "rllib_asor.models.race_net": "rllib_asor.race.net",
    "rllib_asor.models.multi_categorical": "rllib_asor.race.action_dist",
    "rllib_asor.evaluation.race": "rllib_asor.race.evaluation",
    "rllib_asor.rllib.env_registration": "rllib_asor.registry.envs",
    "rllib_asor.rllib.env_families": "rllib_asor.registry.families",
}

OBSERVATION_FILTERS = ("NoFilter", "MeanStdFilter")
# `config.rl_module: {module_class: NAME, model_config: {...}}` (NAME: rllib_asor.registry.models).
RL_MODULE_KEYS = ("module_class", "model_config")


def mean_std_filter_connector(env: Any = None, spaces: Any = None, device: Any = None) -> Any:
    """env_to_module connector factory replacing `observation_filter: MeanStdFilter`."""
    from ray.rllib.connectors.env_to_module import MeanStdFilter

    return MeanStdFilter()


def flatten_observations_connector(env: Any = None, spaces: Any = None, device: Any = None) -> Any:
    """env_to_module connector factory: RLlib's `FlattenObservations` (one-hot for Discrete)."""
    from ray.rllib.connectors.env_to_module import FlattenObservations

    return FlattenObservations()


def translate_config(
    config: dict[str, Any], source: str, prefix: str = "", run: str | None = None
) -> tuple[dict[str, Any], list[str]]:
    """Return (new-stack config dict, warnings); raise UsageError for unsupported legacy values
    (every such key, one line each).

    `model: {...}` becomes `model_config: {...}`, `observation_filter: MeanStdFilter` becomes a
    MeanStdFilter env-to-module connector, the keys the new stack retired go where `retired.py`
    says (`framework: tf` runs as torch, `horizon` is the env's episode limit, ...), and a
    `rollout_fragment_length` shorter than `n_step` is raised to it, as old RLlib did.
    """
    out: dict[str, Any] = {}
    warnings: list[str] = []
    problems = Problems()
    given = config.get("model_config") or {}
    if not isinstance(given, dict):
        problems.add(
            UsageError(
                f"{given!r} is invalid: allowed a mapping of model settings",
                source=source,
                key=f"{prefix}model_config",
            )
        )
        given = {}
    model_config: dict[str, Any] = dict(given)
    into = retired.Into(out, model_config, source, prefix, warnings)
    for key, value in config.items():
        with problems.check():
            _translate_key(key, value, into, run, problems)
    problems.raise_any()
    _fragment_for_n_step(out, source, warnings)
    if model_config:
        out["model_config"] = model_config
    if into.env_config:  # e.g. `horizon`; the file's own env_config wins
        env_config = out.get("env_config")
        out["env_config"] = {**into.env_config, **(env_config if isinstance(env_config, dict) else {})}
    return _moved_paths(out, source, warnings), warnings


def _translate_key(
    key: str, value: Any, into: retired.Into, run: str | None, problems: Problems
) -> None:
    """One config key into `into.out` / `into.model_config`, with its warning; UsageError for
    an unsupported legacy value (each bad `model:` setting kept in `problems`)."""
    out, model_config, source, prefix = into.out, into.model_config, into.source, into.prefix
    if key == "model_config" or retired.translate(key, value, into):
        return
    renamed = {**RENAMED_CONFIG_KEYS, **RENAMED_CONFIG_KEYS_BY_RUN.get(str(run), {})}
    if key in renamed:
        new = renamed[key]
        into.warn(f"legacy key '{key}' translated to '{new}'")
        out[new] = value
    elif key == "model":
        if not isinstance(value, dict):
            raise UsageError(
                f"must be a mapping of model settings, got {value!r}",
                source=source,
                key=f"{prefix}model",
            )
        value = dict(value)
        custom = value.pop("custom_model", None)
        custom_config = value.pop("custom_model_config", None) or {}
        if custom:
            out["rl_module"] = {"module_class": custom}
            for sub, sub_value in dict(custom_config).items():
                model_config.setdefault(sub, sub_value)
            into.warn(
                f"legacy key 'model.custom_model: {custom}' translated to "
                "'rl_module: {module_class: ...}' (custom_model_config -> model_config)"
            )
        if value:
            for sub, sub_value in value.items():
                with problems.check():
                    _check_model_key(sub, source, f"{prefix}model.{sub}")
                    model_config.setdefault(sub, sub_value)
            into.warn(
                f"legacy key 'model' ({', '.join(sorted(value))}) translated to "
                "'model_config' (config.rl_module(model_config=...))"
            )
    elif key == "rl_module":
        block = dict(value) if isinstance(value, dict) else None
        if block is None or "module_class" not in block or set(block) - set(RL_MODULE_KEYS):
            raise UsageError(
                f"{value!r} is invalid: allowed a mapping with 'module_class' (a name such "
                "as race_net or 'package.module:Class') and optional 'model_config'",
                source=source,
                key=f"{prefix}rl_module",
            )
        for sub, sub_value in dict(block.pop("model_config", None) or {}).items():
            model_config.setdefault(sub, sub_value)
        out["rl_module"] = block
    elif key in MODEL_CONFIG_TOPLEVEL_KEYS:
        model_config.setdefault(key, value)
        into.warn(f"legacy key '{key}' translated to 'model_config.{key}'")
    elif key == "observation_filter":
        if value not in OBSERVATION_FILTERS:
            raise UsageError(
                f"{value!r} is invalid: allowed {' | '.join(OBSERVATION_FILTERS)}",
                source=source,
                key=f"{prefix}observation_filter",
            )
        if value == "MeanStdFilter":
            out["env_to_module_connector"] = mean_std_filter_connector
            into.warn(
                "legacy key 'observation_filter: MeanStdFilter' translated to a "
                "MeanStdFilter env-to-module connector"
            )
        else:
            into.warn("legacy key 'observation_filter: NoFilter' ignored")
    else:
        out[key] = value


def _fragment_for_n_step(out: dict[str, Any], source: str, warnings: list[str]) -> None:
    """A fixed `rollout_fragment_length` shorter than a fixed `n_step` raised to it: old RLlib
    did so itself (`max(rollout_fragment_length, n_step)` in DQN's validate_config, SAC's from
    Ray 1.10), RLlib 2.60 refuses the shorter fragment. Grids are left to `build.check_n_step`."""
    n_step, fragment = out.get("n_step"), out.get("rollout_fragment_length")
    longest = n_step[-1] if isinstance(n_step, list | tuple) and n_step else n_step
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in (longest, fragment)):
        return
    if fragment < longest:
        out["rollout_fragment_length"] = longest
        warnings.append(
            f"{source}: 'rollout_fragment_length: {fragment}' translated to "
            f"'rollout_fragment_length: {longest}' (n_step: {n_step}): old RLlib raised the "
            "fragment to n_step itself, RLlib 2.60 refuses a shorter one"
        )


def _moved_paths(value: Any, source: str, warnings: list[str]) -> Any:
    """`value` with every string naming one of our moved modules rewritten to its new path."""
    if isinstance(value, dict):
        return {k: _moved_paths(v, source, warnings) for k, v in value.items()}
    if isinstance(value, list):
        return [_moved_paths(v, source, warnings) for v in value]
    if isinstance(value, str):
        for old, new in MOVED_MODULES.items():
            if value == old or value.startswith((old + ".", old + ":")):
                moved = new + value[len(old) :]
                warnings.append(f"{source}: class path '{value}' moved to '{moved}'")
                return moved
    return value


def _check_model_key(key: str, source: str, shown: str) -> None:
    from dataclasses import fields

    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig

    allowed = sorted(f.name for f in fields(DefaultModelConfig))
    if key not in allowed:
        raise UsageError(
            f"unknown model setting; allowed: {', '.join(allowed)}", source=source, key=shown
        )


def translate_stop(
    stop: dict[str, Any], source: str, prefix: str = "stop."
) -> tuple[dict[str, Any], list[str]]:
    """Rename old result names in a stop dict; values must be numbers (UsageError naming every
    key that is not)."""
    out: dict[str, Any] = {}
    warnings: list[str] = []
    problems = Problems()
    for key, value in stop.items():
        if isinstance(value, bool) or not isinstance(value, int | float):
            problems.add(
                UsageError(
                    f"stop value {value!r} is invalid: allowed a number",
                    source=source,
                    key=f"{prefix}{key}",
                )
            )
            continue
        if key in RENAMED_STOP_KEYS:
            new = RENAMED_STOP_KEYS[key]
            warnings.append(f"{source}: legacy stop key '{key}' translated to '{new}'")
            key = new
        out[key] = value
    problems.raise_any()
    return out, warnings
