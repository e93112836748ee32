"""Parse: an experiment file in the old RLlib YAML format into `Experiment`s.

One file holds one or more experiments: `name: {env, run, stop, config, checkpoint_config}`.
Legacy keys are translated on the way (`legacy.py`); nothing here needs Ray."""

from __future__ import annotations

import copy
import json
import os
import re
from dataclasses import dataclass, field
from typing import Any

import yaml

from rllib_asor.cli import grid, legacy
from rllib_asor.cli.errors import UsageError

SPEC_KEYS = ("env", "run", "stop", "config", "checkpoint_config", "num_samples", "storage_path")


CHECKPOINT_KEYS = (
    "checkpoint_frequency",
    "checkpoint_at_end",
    "num_to_keep",
    "checkpoint_score_attribute",
    "checkpoint_score_order",
)


DEFAULT_NUM_TO_KEEP = 3
ESCP_KEY = "escp_settings"
"""Where an `escp:` block goes (`EscpConfig.escp_settings`; validated in validate.py)."""
MAPLE_KEY = "maple_settings"
"""Where a `maple:` block goes (`MapleConfig.maple_settings`; validated in validate.py)."""


@dataclass
class Experiment:
    """One experiment, translated to new-stack names; grids still in YAML form."""

    name: str
    run: str
    env: str
    source: str
    config: dict[str, Any] = field(default_factory=dict)
    asor: dict[str, Any] | None = None
    stop: dict[str, Any] = field(default_factory=dict)
    checkpoint_config: dict[str, Any] = field(default_factory=dict)
    num_samples: int = 1
    storage_path: str | None = None
    warnings: list[str] = field(default_factory=list)

    @property
    def num_trials(self) -> int:
        return grid.count_trials(self.config, self.asor) * self.num_samples


def load_file(path: str) -> list[Experiment]:
    """Parse a YAML experiment file into experiments (not yet validated against RLlib)."""
    if not os.path.isfile(path):
        raise UsageError("file not found (expected a YAML experiment file)", source=path)
    try:
        with open(path, encoding="utf-8") as f:
            data = yaml.safe_load(f)
    except yaml.YAMLError as e:
        where = ""
        mark = getattr(e, "problem_mark", None)
        if mark is not None:
            where = f"line {mark.line + 1}, column {mark.column + 1}: "
        problem = getattr(e, "problem", None) or str(e).splitlines()[0]
        raise UsageError(f"invalid YAML: {where}{problem}", source=path) from None
    except OSError as e:
        raise UsageError(f"cannot read file: {e.strerror}", source=path) from None
    if not isinstance(data, dict) or not data:
        raise UsageError(
            "expected a mapping 'experiment-name: {env, run, stop, config}'", source=path
        )
    return [parse_experiment(str(name), spec, path) for name, spec in data.items()]


def _score_attribute(value: Any, ckpt: dict[str, Any], source: str, warns: list[str]) -> Any:
    """Old `checkpoint_score_attr` as Tune translated it (`tune.run`): a `min-` prefix means
    `checkpoint_score_order: min` (else max); an old result name becomes its new one."""
    if not isinstance(value, str):
        return value
    order = "max"
    if value.startswith("min-"):
        value, order = value[4:], "min"
    ckpt.setdefault("checkpoint_score_order", order)
    new = legacy.RENAMED_STOP_KEYS.get(value)
    if new is not None:
        warns.append(f"{source}: legacy result name '{value}' translated to '{new}'")
        value = new
    return value


def absolute_input(value: Any) -> Any:
    """Offline `input` paths made absolute against the launch directory: Tune runs each trial
    in its own directory, where a relative `data/offline/...` would not be found."""
    if isinstance(value, list):
        return [absolute_input(v) for v in value]
    if isinstance(value, str) and value != "sampler" and "://" not in value:
        return os.path.abspath(value)
    return value


def parse_experiment(name: str, spec: Any, source: str) -> Experiment:
    """Translate one `name: {...}` entry (legacy keys renamed with a warning)."""
    if not isinstance(spec, dict):
        raise UsageError(
            f"must be a mapping with keys {', '.join(SPEC_KEYS)}", source=source, key=name
        )
    spec = copy.deepcopy(spec)
    warns: list[str] = []
    ckpt = _mapping(spec.pop("checkpoint_config", None) or {}, source, f"{name}.checkpoint_config")
    for old, (section, new) in legacy.RENAMED_SPEC_KEYS.items():
        if old in spec:
            value = spec.pop(old)
            if section == "checkpoint_config":
                if old == "checkpoint_score_attr":
                    value = _score_attribute(value, ckpt, source, warns)
                ckpt.setdefault(new, value)
                warns.append(
                    f"{source}: legacy key '{old}' translated to 'checkpoint_config.{new}'"
                )
            else:
                spec.setdefault(new, value)
                warns.append(f"{source}: legacy key '{old}' translated to '{new}'")
    unknown = sorted(set(spec) - set(SPEC_KEYS))
    if unknown:
        raise UsageError(
            f"unknown key; allowed: {', '.join(SPEC_KEYS)}",
            source=source,
            key=f"{name}.{unknown[0]}",
        )
    bad_ckpt = sorted(set(ckpt) - set(CHECKPOINT_KEYS))
    if bad_ckpt:
        raise UsageError(
            f"unknown key; allowed: {', '.join(CHECKPOINT_KEYS)}",
            source=source,
            key=f"{name}.checkpoint_config.{bad_ckpt[0]}",
        )
    config = _mapping(spec.get("config") or {}, source, f"{name}.config")
    asor = config.pop("asor", None)
    if asor is not None:
        asor = _mapping(asor, source, f"{name}.config.asor")
    maple = config.pop("maple", None)
    escp = config.pop("escp", None)
    config, more = legacy.translate_config(config, source, f"{name}.config.", spec.get("run"))
    warns += more
    if maple is not None:  # MAPLE/MOPO's own block: the MapleConfig attribute `maple_settings`
        config[MAPLE_KEY] = _mapping(maple, source, f"{name}.config.maple")
    if escp is not None:  # ESCP's own block: the EscpConfig attribute `escp_settings`
        config[ESCP_KEY] = _mapping(escp, source, f"{name}.config.escp")
    if "input" in config:
        config["input"] = absolute_input(config["input"])
    stop, more = legacy.translate_stop(
        _mapping(spec.get("stop") or {}, source, f"{name}.stop"), source, f"{name}.stop."
    )
    warns += more
    env = spec.get("env", config.pop("env", None))
    run = spec.get("run")
    if not isinstance(run, str) or not run:
        raise UsageError(
            "missing or not a string; allowed: an RLlib algorithm name such as PPO",
            source=source,
            key=f"{name}.run",
        )
    if not isinstance(env, str) or not env:
        raise UsageError(
            "missing or not a string; allowed: a registered env id such as CartPole-v1",
            source=source,
            key=f"{name}.env",
        )
    num_samples = spec.get("num_samples", 1)
    if isinstance(num_samples, bool) or not isinstance(num_samples, int) or num_samples < 1:
        raise UsageError(
            f"{num_samples!r} is invalid: allowed an integer >= 1",
            source=source,
            key=f"{name}.num_samples",
        )
    return Experiment(
        name=name,
        run=run,
        env=env,
        source=source,
        config=config,
        asor=asor,
        stop=stop,
        checkpoint_config=ckpt,
        num_samples=num_samples,
        storage_path=spec.get("storage_path"),
        warnings=warns,
    )


def from_flags(run: str, env: str, config_json: str | None, name: str | None = None) -> Experiment:
    """Build an experiment from `--run/--env/--config` (same pipeline as a YAML file)."""
    config: Any = {}
    if config_json:
        try:
            config = json.loads(config_json)
        except json.JSONDecodeError as e:
            raise UsageError(
                f"invalid JSON: {e.msg} at column {e.colno}", source="--config"
            ) from None
    name = name or re.sub(r"[^A-Za-z0-9_.-]+", "_", f"{run}_{env}")
    return parse_experiment(name, {"run": run, "env": env, "config": config}, "--config")


def _mapping(value: Any, source: str, key: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise UsageError(f"{value!r} is invalid: allowed a mapping", source=source, key=key)
    return dict(value)
