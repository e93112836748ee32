"""Parse: an experiment file in the old RLlib YAML format into `Experiment`s.

One file holds one or more experiments: `name: {env, run, stop, config, checkpoint_config}`.
Legacy keys are translated on the way (`legacy.py`); nothing here needs Ray."""

from __future__ import annotations

import copy
import importlib
import json
import os
import re
from dataclasses import dataclass, field
from typing import Annotated, Any

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from rllib_asor.cli import grid, legacy
from rllib_asor.cli.errors import Problems, UsageError
from rllib_asor.settings_model import Allowed, allowed_text, one_of

DEFAULT_NUM_TO_KEEP = 3


class CheckpointSettings(BaseModel):
    """`checkpoint_config:` of an experiment (the arguments of Tune's `CheckpointConfig`)."""

    model_config = ConfigDict(extra="forbid", strict=True, use_attribute_docstrings=True)

    checkpoint_frequency: Annotated[int, Field(ge=0), Allowed("an integer >= 0")] = 0
    """Save a checkpoint every this many training iterations (0: none on the way)."""
    checkpoint_at_end: Annotated[bool | None, Allowed("true or false")] = True
    """Save one when the trial ends."""
    num_to_keep: Annotated[
        Annotated[int, Field(ge=1)] | None, Allowed("an integer >= 1 or null")
    ] = DEFAULT_NUM_TO_KEEP
    """Checkpoints kept per trial (the best by `checkpoint_score_attribute`, else the latest);
    null keeps all."""
    checkpoint_score_attribute: Annotated[str | None, Allowed("a result name")] = None
    """Result name that ranks checkpoints, e.g. env_runners/episode_return_mean."""
    checkpoint_score_order: one_of(("max", "min")) = "max"
    """Keep the highest (max) or the lowest (min) scores."""


class ExperimentSpec(BaseModel):
    """One experiment of a YAML file, `name: {env, run, stop, config, checkpoint_config}` (the
    old RLlib format; its legacy keys are translated with a warning)."""

    model_config = ConfigDict(extra="forbid", strict=True, use_attribute_docstrings=True)

    env: Annotated[str, Field(min_length=1), Allowed("a registered env id such as CartPole-v1")]
    """The env: a registered id (CartPole-v1, rllib_asor/LavaWorld-v0,
    game_env/ObstacleRace-v0), `module:EnvId` or a class path. `config.env` may give it instead."""
    run: Annotated[str, Field(min_length=1), Allowed("an RLlib algorithm name such as PPO")]
    """The algorithm: an RLlib name (PPO, SAC, CQL, ...) or one of ours (ESCP, MAPLE, MOPO)."""
    stop: dict[str, float] = {}
    """When a trial stops: a result name and the value that ends it (training_iteration,
    num_env_steps_sampled_lifetime, env_runners/episode_return_mean, time_total_s, ...)."""
    config: dict[str, Any] = {}
    """The AlgorithmConfig settings by name (old names are translated with a warning), any
    value may be `{grid_search: [...]}`; our own blocks: `asor:`, `escp:`, `maple:`, `dara:`, `osi:`,
    `cadm:`, `gaifo:`, `garat:`, `bco:`, `soil:`."""
    checkpoint_config: CheckpointSettings = CheckpointSettings()
    """When checkpoints are saved and how many are kept."""
    num_samples: Annotated[int, Field(ge=1), Allowed("an integer >= 1")] = 1
    """Trials per grid point (Tune's num_samples)."""
    storage_path: Annotated[str | None, Allowed("a directory path")] = None
    """Directory for the results (default ~/ray_results)."""


SPEC_KEYS = tuple(ExperimentSpec.model_fields)
ESCP_KEY = "escp_settings"
"""Where an `escp:` block goes (`EscpConfig.escp_settings`; validated in validate.py)."""
MAPLE_KEY = "maple_settings"
"""Where a `maple:` block goes (`MapleConfig.maple_settings`; validated in validate.py)."""


@dataclass(frozen=True)
class SettingsBlock:
    """One of our blocks in `config:`: the class that declares it, the runs it goes with
    (None: any run the ASOR wiring supports) and the config key the parser moves it to
    (None: `Experiment.asor`)."""

    settings: str
    """"module:Class" of its `Settings` declaration."""
    runs: tuple[str, ...] | None
    key: str | None
    aliases: dict[str, str] = field(default_factory=dict)
    """Other names of a field (`lambda` for `lambda_`)."""

    def settings_class(self) -> type:
        module, _, name = self.settings.partition(":")
        return getattr(importlib.import_module(module), name)


SETTINGS_BLOCKS: dict[str, SettingsBlock] = {
    "asor": SettingsBlock("rllib_asor.asor.config:AsorConfig", None, None, {"lambda": "lambda_"}),
    "escp": SettingsBlock("rllib_asor.algorithms.escp.settings:EscpSettings", ("ESCP",), ESCP_KEY),
    "maple": SettingsBlock(
        "rllib_asor.algorithms.maple.settings:MapleSettings", ("MAPLE", "MOPO"), MAPLE_KEY
    ),
    "dara": SettingsBlock(
        "rllib_asor.algorithms.dara.settings:DaraSettings", ("MAPLE", "MOPO"), "dara_settings"
    ),
    "osi": SettingsBlock(
        "rllib_asor.algorithms.osi.settings:OsiSettings", ("OSI",), "osi_settings"
    ),
    "cadm": SettingsBlock(
        "rllib_asor.algorithms.cadm.settings:CadmSettings", ("CaDM",), "cadm_settings"
    ),
    "gaifo": SettingsBlock(
        "rllib_asor.algorithms.gaifo.settings:GaifoSettings", ("GAIfO",), "gaifo_settings"
    ),
    "garat": SettingsBlock(
        "rllib_asor.algorithms.garat.settings:GaratSettings", ("GARAT",), "garat_settings"
    ),
    "bco": SettingsBlock(
        "rllib_asor.algorithms.bco.settings:BcoSettings", ("BCO",), "bco_settings"
    ),
    "soil": SettingsBlock(
        "rllib_asor.algorithms.soil.settings:SoilSettings", ("SOIL",), "soil_settings"
    ),
}
"""Our `config:` blocks by name; validate.py checks each, `rllib schema` describes each."""


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


def load_file(path: str, problems: Problems | None = None) -> list[Experiment]:
    """Parse a YAML experiment file into experiments (not yet validated against RLlib); a
    UsageError names every experiment's problems, or with `problems` they are kept there and
    the other experiments returned (so that their later checks report theirs too)."""
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
    found = Problems() if problems is None else problems  # every experiment's at once
    exps = []
    for name, spec in data.items():
        with found.check():
            exps.append(parse_experiment(str(name), spec, path))
    if problems is None:
        found.raise_any()
    return exps


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
    """Translate one `name: {...}` entry (legacy keys renamed with a warning); a UsageError
    names every problem of the entry (one line each)."""
    if not isinstance(spec, dict):
        raise UsageError(
            f"must be a mapping with keys {', '.join(SPEC_KEYS)}", source=source, key=name
        )
    spec = copy.deepcopy(spec)
    warns: list[str] = []
    problems = Problems()
    ckpt = _mapping_or_none(
        spec.pop("checkpoint_config", None), problems, source, f"{name}.checkpoint_config"
    )
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
    config = _mapping_or_none(spec.get("config"), problems, source, f"{name}.config")
    given = {block: config.pop(block) for block in SETTINGS_BLOCKS if block in config}
    blocks = {
        block: _mapping_or_none(value, problems, source, f"{name}.config.{block}")
        for block, value in given.items()
        if value is not None  # `asor: null`: no block
    }
    with problems.check():
        config, more = legacy.translate_config(config, source, f"{name}.config.", spec.get("run"))
        warns += more
    asor = blocks.pop("asor", None)
    for block, settings in blocks.items():  # e.g. `maple:` -> MapleConfig.maple_settings
        config[SETTINGS_BLOCKS[block].key or block] = settings
    if "input" in config:
        config["input"] = absolute_input(config["input"])
    stop: dict[str, Any] = {}
    with problems.check():
        given_stop = _mapping_or_none(spec.get("stop"), problems, source, f"{name}.stop")
        stop, more = legacy.translate_stop(given_stop, source, f"{name}.stop.")
        warns += more
    env = spec.get("env", config.pop("env", None))
    checked = {**spec, "env": env, "stop": stop, "config": {}, "checkpoint_config": ckpt}
    try:
        ExperimentSpec.model_validate({k: v for k, v in checked.items() if v is not None})
    except ValidationError as e:
        for problem in _spec_problems(e, name, source, checked):
            problems.add(problem)
    problems.raise_any()
    return Experiment(
        name=name,
        run=spec["run"],
        env=env,
        source=source,
        config=config,
        asor=asor,
        stop=stop,
        checkpoint_config=ckpt,
        num_samples=spec.get("num_samples", 1),
        storage_path=spec.get("storage_path"),
        warnings=warns,
    )


def _spec_problems(
    error: ValidationError, name: str, source: str, given: dict[str, Any]
) -> list[UsageError]:
    """Every problem `ExperimentSpec` found, one line each naming its key."""
    out = []
    for problem in error.errors():
        path = [str(part) for part in problem["loc"]]
        model: type[BaseModel] = ExperimentSpec
        values = given
        if path[0] == "checkpoint_config" and len(path) > 1:
            model, path, values = CheckpointSettings, path[:2], given["checkpoint_config"]
        else:
            path = path[:1]
        key = f"{name}.{'.'.join(path)}"
        if problem["type"] == "extra_forbidden":
            message = f"unknown key; allowed: {', '.join(model.model_fields)}"
        elif values.get(path[-1]) is None:
            message = f"missing; allowed: {allowed_text(model, path[-1])}"
        else:
            message = f"{values[path[-1]]!r} is invalid: allowed {allowed_text(model, path[-1])}"
        out.append(UsageError(message, source=source, key=key))
    return out


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


def _mapping_or_none(value: Any, problems: Problems, source: str, key: str) -> dict[str, Any]:
    """`value` (None: empty) as a dict; anything else is a problem (and an empty dict)."""
    if value is None or isinstance(value, dict):
        return dict(value or {})
    problems.add(UsageError(f"{value!r} is invalid: allowed a mapping", source=source, key=key))
    return {}
