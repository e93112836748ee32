"""Every legacy rename and move of `rllib_asor.cli.legacy`, driven by its own tables:
the new name is a real setting of the new API stack (a config attribute, a result key, a Tune
checkpoint/run setting, an importable module) and the value lands there, with a warning naming
both. New table entries are covered without touching this file."""

from __future__ import annotations

import dataclasses
import importlib

import pytest
from ray.rllib.algorithms.dqn import DQNConfig
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
from ray.rllib.utils import metrics as M
from ray.tune import CheckpointConfig

from rllib_asor.cli import legacy, spec

CONFIG_CLASSES = (PPOConfig, SACConfig, DQNConfig)


def _config_class(key: str):
    for cls in CONFIG_CLASSES:
        if hasattr(cls(), key):
            return cls
    return None


def _other_value(default):
    """A value of the setting's type that differs from its default."""
    if isinstance(default, bool):
        return not default
    if isinstance(default, int | float):
        return default + 7
    if isinstance(default, dict):
        return {"custom_resource": 2}
    return 17


@pytest.mark.parametrize("old, new", sorted(legacy.RENAMED_CONFIG_KEYS.items()))
def test_renamed_config_key_lands_on_a_real_setting(old, new):
    cls = _config_class(new)
    assert cls is not None, f"{old} -> {new}: no such setting on {[c.__name__ for c in CONFIG_CLASSES]}"
    value = _other_value(getattr(cls(), new))
    out, warnings = legacy.translate_config({old: value}, "f.yaml")
    assert out == {new: value}
    assert any(f"'{old}'" in w and f"'{new}'" in w for w in warnings), warnings
    config = cls().update_from_dict(out)
    assert getattr(config, new) == value
    assert getattr(config, new) != getattr(cls(), new)


@pytest.mark.parametrize(
    "run, old, new",
    sorted((r, o, n) for r, t in legacy.RENAMED_CONFIG_KEYS_BY_RUN.items() for o, n in t.items()),
)
def test_a_rename_of_one_run_applies_to_that_run_only(run, old, new):
    from ray.tune.registry import get_trainable_cls

    cls = get_trainable_cls(run).get_default_config().__class__
    out, warnings = legacy.translate_config({old: 7}, "f.yaml", run=run)
    assert out == {new: 7}
    assert any(f"'{old}'" in w and f"'{new}'" in w for w in warnings), warnings
    assert getattr(cls().update_from_dict(out), new) == 7
    other, _ = legacy.translate_config({old: 7}, "f.yaml", run="PPO")
    assert new not in other


@pytest.mark.parametrize("key", legacy.MODEL_CONFIG_TOPLEVEL_KEYS)
def test_top_level_model_keys_land_in_model_config(key):
    assert key in {f.name for f in dataclasses.fields(DefaultModelConfig)}
    default = getattr(DefaultModelConfig(), key)
    out, warnings = legacy.translate_config({key: not default}, "f.yaml")
    assert out == {"model_config": {key: not default}}
    assert any(key in w for w in warnings)
    assert PPOConfig().rl_module(model_config=out["model_config"]).model_config[key] is (not default)


def _result_keys() -> set[str]:
    episode = (M.EPISODE_RETURN_MEAN, M.EPISODE_RETURN_MAX, M.EPISODE_RETURN_MIN, M.EPISODE_LEN_MEAN)
    keys = {f"{M.ENV_RUNNER_RESULTS}/{k}" for k in episode}
    keys |= {f"{M.EVALUATION_RESULTS}/{M.ENV_RUNNER_RESULTS}/{k}" for k in episode}
    keys |= {M.NUM_ENV_STEPS_SAMPLED_LIFETIME}
    keys |= {f"{M.ENV_RUNNER_RESULTS}/{M.NUM_AGENT_STEPS_SAMPLED_LIFETIME}/default_agent"}
    return keys


@pytest.mark.parametrize("old, new", sorted(legacy.RENAMED_STOP_KEYS.items()))
def test_renamed_stop_key_is_a_result_key_of_the_new_stack(old, new):
    assert new in _result_keys()
    out, warnings = legacy.translate_stop({old: 123.5, "training_iteration": 3}, "f.yaml")
    assert out == {new: 123.5, "training_iteration": 3}
    assert any(f"'{old}'" in w and f"'{new}'" in w for w in warnings)


@pytest.mark.parametrize("value", [True, "high", None])
def test_stop_values_must_be_numbers(value):
    with pytest.raises(Exception, match="allowed a number"):
        legacy.translate_stop({"episode_reward_mean": value}, "f.yaml")


@pytest.mark.parametrize("old, target", sorted(legacy.RENAMED_SPEC_KEYS.items()))
def test_renamed_experiment_key_lands_in_the_tune_setting(old, target, tmp_path):
    section, new = target
    value = {"checkpoint_at_end": True, "checkpoint_score_attr": "env_runners/episode_return_mean"}
    value = value.get(old, 3) if section else str(tmp_path)  # a value each key takes
    exp = spec.parse_experiment("e", {"run": "PPO", "env": "CartPole-v1", old: value}, "f.yaml")
    if section == "checkpoint_config":
        assert new in {f.name for f in dataclasses.fields(CheckpointConfig)}
        assert exp.checkpoint_config[new] == value
    else:
        assert getattr(exp, new) == value
    assert any(f"'{old}'" in w and new in w for w in exp.warnings)


@pytest.mark.parametrize("old, new", sorted(legacy.MOVED_MODULES.items()))
def test_moved_class_paths_point_at_importable_modules(old, new):
    importlib.import_module(new)
    out, warnings = legacy.translate_config(
        {"callbacks": f"{old}:Thing", "nested": {"classes": [f"{old}.Thing", "other.module"]}},
        "f.yaml",
    )
    assert out["callbacks"] == f"{new}:Thing"
    assert out["nested"]["classes"] == [f"{new}.Thing", "other.module"]
    assert sum(old in w for w in warnings) == 2
    same, none = legacy.translate_config({"x": old + "_suffix"}, "f.yaml")  # not a prefix match
    assert same == {"x": old + "_suffix"} and none == []


def test_model_block_and_filters_translate_to_the_new_places():
    out, warnings = legacy.translate_config(
        {"model": {"fcnet_hiddens": [8], "custom_model": "race_net", "custom_model_config": {"a": 1}},
         "observation_filter": "MeanStdFilter", "vf_share_layers": True, "lr": 0.1},
        "f.yaml",
    )
    assert out["rl_module"] == {"module_class": "race_net"}
    assert out["model_config"] == {"fcnet_hiddens": [8], "a": 1, "vf_share_layers": True}
    assert out["env_to_module_connector"] is legacy.mean_std_filter_connector
    assert out["lr"] == 0.1
    assert len(warnings) == 4
    out, warnings = legacy.translate_config({"observation_filter": "NoFilter"}, "f.yaml")
    assert out == {} and "ignored" in warnings[0]
    with pytest.raises(Exception, match="allowed NoFilter | MeanStdFilter"):
        legacy.translate_config({"observation_filter": "Clip"}, "f.yaml")
    with pytest.raises(Exception, match="unknown model setting"):
        legacy.translate_config({"model": {"fcnet_hidens": [8]}}, "f.yaml")
    with pytest.raises(Exception, match="mapping of model settings"):
        legacy.translate_config({"model": [8]}, "f.yaml")
    out, _ = legacy.translate_config(
        {"rl_module": {"module_class": "race_net", "model_config": {"b": 2}}, "model_config": {"c": 3}},
        "f.yaml",
    )
    assert out == {"rl_module": {"module_class": "race_net"}, "model_config": {"c": 3, "b": 2}}
    with pytest.raises(Exception, match="module_class"):
        legacy.translate_config({"rl_module": {"model_config": {}}}, "f.yaml")
