"""Experiments in the old RLlib YAML format: load, translate, validate, build the Tune param space.

One file holds one or more experiments: `name: {env, run, stop, config, checkpoint_config}`.
Everything that can be wrong with the input is found here, before Ray starts, and raised as a
`UsageError` naming the file, the key and what is allowed.
"""

from __future__ import annotations

import contextlib
import copy
import difflib
import json
import logging
import os
import re
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import yaml

from rllib_asor.cli import grid, legacy, multi_agent
from rllib_asor.cli.errors import UsageError
from rllib_asor.rllib.env_families import families_with_curriculum, family_of

SPEC_KEYS = ("env", "run", "stop", "config", "checkpoint_config", "num_samples", "storage_path")
CHECKPOINT_KEYS = (
    "checkpoint_frequency",
    "checkpoint_at_end",
    "num_to_keep",
    "checkpoint_score_attribute",
    "checkpoint_score_order",
)
DEFAULT_NUM_TO_KEEP = 3
# Config keys that are not plain AlgorithmConfig attributes but that we apply ourselves.
SPECIAL_CONFIG_KEYS = (
    "model_config",
    "env_config",
    "env_to_module_connector",
    "rl_module",
    "multi_agent",
    "curriculum",
)
# Config key (as written) -> key in AlgorithmConfig.to_dict() (the Tune param space).
PARAM_SPACE_KEYS = {
    "model_config": "_model_config",
    "train_batch_size_per_learner": "_train_batch_size_per_learner",
    "env_to_module_connector": "_env_to_module_connector",
    "rl_module": "_rl_module_spec",
    "lambda_": "lambda",
    "input_": "input",
    "framework_str": "framework",
    "callbacks_class": "callbacks",
    "create_env_on_local_worker": "create_env_on_driver",
    "custom_evaluation_function": "custom_eval_function",
}
# Settings of `--test`: a tiny local run that works on 2 cores.
TEST_STOP = {"training_iteration": 2}
TEST_ENV_RUNNERS = 2
TEST_CPUS_PER_ENV_RUNNER = 0.5
TEST_BATCH = 256
TEST_MINIBATCH = 64
TEST_DATASET_ITERS = 2


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


# ---------------------------------------------------------------------------------- loading
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


def _absolute_input(value: Any) -> Any:
    """Offline `input` paths made absolute against the launch directory: Tune runs each trial
    in its own directory, where a relative `data/offline/...` would not be found."""
    if isinstance(value, list):
        return [_absolute_input(v) for v in value]
    if isinstance(value, str) and value != "sampler" and "://" not in value:
        return os.path.abspath(value)
    return value


def missing_inputs(value: Any) -> list[str]:
    """The local paths of an offline `input` value that do not exist."""
    paths = value if isinstance(value, list) else [value]
    return [p for p in paths if isinstance(p, str) and os.path.isabs(p) and not os.path.exists(p)]


def check_offline_input(exp: Experiment) -> None:
    """A local offline `input` that does not exist fails here, before Ray starts."""
    missing = missing_inputs(exp.config.get("input"))
    if missing:
        hint = (
            "; make the offline datasets first: `make datasets` (about 10 minutes on 2 cores, "
            "docs/offline.md)"
            if any("data/offline" in p for p in missing)
            else ""
        )
        raise UsageError(
            f"offline input {missing[0]} does not exist{hint}",
            source=exp.source,
            key=f"{exp.name}.config.input",
        )


def _tiny_test_data(exp: Experiment) -> None:
    """--test on a fresh clone: stand-ins for the missing datasets, in a temporary folder."""
    missing = missing_inputs(exp.config.get("input"))
    if not missing:
        return
    import atexit
    import shutil
    import tempfile

    from rllib_asor.data.collect import TINY_STEPS, tiny_datasets

    tmp = tempfile.mkdtemp(prefix="rllib-asor-test-data-")
    atexit.register(shutil.rmtree, tmp, ignore_errors=True)
    print(
        f"rllib: --test: {len(missing)} offline dataset(s) missing (e.g. {missing[0]}); building "
        f"tiny stand-ins ({TINY_STEPS} steps each, untrained policy; not for results) ...",
        flush=True,
    )
    with _quiet():
        swap = tiny_datasets(exp.env, missing, tmp)
    value = exp.config["input"]
    exp.config["input"] = (
        [swap.get(p, p) for p in value] if isinstance(value, list) else swap.get(value, value)
    )
    exp.warnings.append(
        f"--test: trained on tiny stand-in datasets in {tmp} (deleted at exit); "
        "for real runs make the data first: `make datasets`"
    )


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
    config, more = legacy.translate_config(config, source, f"{name}.config.")
    warns += more
    if "input" in config:
        config["input"] = _absolute_input(config["input"])
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


# ---------------------------------------------------------------------------------- overrides
def parse_stop_flags(items: list[str] | None) -> dict[str, Any]:
    """`--stop KEY=VALUE` (repeatable) -> {key: number}, legacy names translated."""
    stop: dict[str, Any] = {}
    for item in items or []:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise UsageError(
                f"{item!r} is invalid: allowed KEY=VALUE, e.g. training_iteration=10", key="--stop"
            )
        stop[key] = _number(raw.strip())
    translated, _ = legacy.translate_stop(stop, "", "--stop ")
    return translated


def _number(raw: str) -> Any:
    """'10' -> 10, '1e5' -> 100000.0, anything else stays a string."""
    for cast in (int, float):
        try:
            return cast(raw)
        except ValueError:
            pass
    return raw


def apply_overrides(
    exp: Experiment,
    *,
    test: bool = False,
    num_env_runners: int | None = None,
    stop: dict[str, Any] | None = None,
    checkpoint_freq: int | None = None,
    keep_checkpoints: int | None = None,
) -> None:
    """Apply command-line options on top of the file's values (in place)."""
    cfg = exp.config
    if test:
        offline = cfg.get("input", "sampler") != "sampler"
        if offline:  # data from files: few dataset passes, the file's env runners (often 0)
            cfg["dataset_num_iters_per_learner"] = TEST_DATASET_ITERS
            _tiny_test_data(exp)
        else:
            cfg["num_env_runners"] = TEST_ENV_RUNNERS
            cfg["num_cpus_per_env_runner"] = TEST_CPUS_PER_ENV_RUNNER
            cfg["num_envs_per_env_runner"] = 1
            family = family_of(exp.env)
            if family is not None and family.test_env_config:
                cfg["env_config"] = {**(cfg.get("env_config") or {}), **family.test_env_config}
        cfg["num_learners"] = 0
        cfg["evaluation_interval"] = None
        cfg.pop("train_batch_size_per_learner", None)
        cfg["train_batch_size"] = TEST_BATCH
        if exp.run.upper() in ("PPO", "APPO", "IMPALA"):
            cfg["minibatch_size"] = TEST_MINIBATCH
            cfg["num_epochs"] = 1
        if "rollout_fragment_length" in cfg:
            cfg["rollout_fragment_length"] = "auto"
        exp.stop = dict(TEST_STOP)
    if num_env_runners is not None:
        if num_env_runners < 0:
            raise UsageError(
                f"{num_env_runners} is invalid: allowed an integer >= 0", key="--num-env-runners"
            )
        cfg["num_env_runners"] = num_env_runners
    if stop:
        exp.stop = {**exp.stop, **stop} if not test else dict(stop)
    if checkpoint_freq is not None:
        if checkpoint_freq < 0:
            raise UsageError(
                f"{checkpoint_freq} is invalid: allowed an integer >= 0", key="--checkpoint-freq"
            )
        exp.checkpoint_config["checkpoint_frequency"] = checkpoint_freq
    if keep_checkpoints is not None:
        if keep_checkpoints < 1:
            raise UsageError(
                f"{keep_checkpoints} is invalid: allowed an integer >= 1", key="--keep-checkpoints"
            )
        exp.checkpoint_config["num_to_keep"] = keep_checkpoints


def checkpoint_kwargs(exp: Experiment) -> dict[str, Any]:
    """Arguments of tune.CheckpointConfig: keep the last 3 and one at the end by default."""
    out = {"num_to_keep": DEFAULT_NUM_TO_KEEP, "checkpoint_at_end": True}
    out.update(exp.checkpoint_config)
    return out


# ---------------------------------------------------------------------------------- validation
@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """Keep RLlib's import-time/log warnings off stderr while we validate."""
    prev = logging.root.manager.disable
    logging.disable(logging.WARNING)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            yield
    finally:
        logging.disable(prev)


PPO_ONLY_LEARNER_KEYS = ("overlap_sampling", "drop_bootstrap_rows")
"""`learner_config_dict` switches of ours that only PPO reads (docs/speed.md)."""


def algorithm_class(exp: Experiment) -> type:
    """The RLlib Algorithm class for `exp.run` (UsageError if unknown)."""
    from ray.rllib.algorithms.registry import ALGORITHMS
    from ray.tune.registry import get_trainable_cls

    learner_dict = exp.config.get("learner_config_dict")
    learner_dict = learner_dict if isinstance(learner_dict, dict) else {}
    for key in PPO_ONLY_LEARNER_KEYS:
        if learner_dict.get(key) and exp.run != "PPO":
            raise UsageError(
                f"works with run: PPO only, not {exp.run}",
                source=exp.source,
                key=f"{exp.name}.config.learner_config_dict.{key}",
            )
    if learner_dict.get("overlap_sampling"):
        from rllib_asor.rllib.overlap import OverlappedPPO

        return OverlappedPPO  # PPO whose env runners sample during the update
    try:
        with _quiet():
            return get_trainable_cls(exp.run)
    except Exception:
        allowed = ", ".join(sorted(ALGORITHMS))
        raise UsageError(
            f"unknown algorithm {exp.run!r}; allowed: {allowed}",
            source=exp.source,
            key=f"{exp.name}.run",
        ) from None


def _attr_name(key: str) -> str:
    from ray.rllib.algorithms.algorithm_config import AlgorithmConfig

    return AlgorithmConfig._translate_special_keys(key, warn_deprecated=False)


def _check_key(default_cfg: Any, key: str, exp: Experiment) -> None:
    from ray._common.deprecation import DEPRECATED_VALUE

    if key in SPECIAL_CONFIG_KEYS:
        return
    attr = _attr_name(key)
    cls_attr = getattr(type(default_cfg), attr, None)
    known = attr in vars(default_cfg) or (
        isinstance(cls_attr, property) and cls_attr.fset is not None
    )
    where = f"{exp.name}.config.{key}"
    algo = type(default_cfg).__name__
    if not known:
        names = sorted(k for k in vars(default_cfg) if not k.startswith("_")) + list(
            SPECIAL_CONFIG_KEYS
        )
        close = difflib.get_close_matches(key, names, n=3)
        hint = f"did you mean {' or '.join(close)}? " if close else ""
        raise UsageError(
            f"unknown key for {exp.run}; {hint}allowed: the settings of {algo} "
            f"(e.g. lr, gamma, train_batch_size, num_env_runners, model_config) and 'asor'",
            source=exp.source,
            key=where,
        )
    if getattr(default_cfg, attr, None) == DEPRECATED_VALUE:
        raise UsageError(
            f"is deprecated and has no effect on RLlib's new API stack ({algo})",
            source=exp.source,
            key=where,
        )


def build_algo_config(exp: Experiment, choice: dict[grid.Path, Any] | None = None) -> Any:
    """AlgorithmConfig for one grid point (default: first candidate of every grid)."""
    cls = algorithm_class(exp)
    with _quiet():
        cfg = cls.get_default_config()
        for key in exp.config:
            _check_key(cfg, key, exp)
        values = grid.with_candidates(exp.config, choice)
        family = family_of(exp.env)
        if family is not None:
            values = {**family.config_defaults, **values}
        model_config = values.pop("model_config", None)
        env_config = values.pop("env_config", None) or {}
        connector = values.pop("env_to_module_connector", None)
        rl_module = values.pop("rl_module", None)
        multi = values.pop("multi_agent", None)
        curriculum = _curriculum(values.pop("curriculum", None), exp)
        if multi is not None:
            try:
                cfg.multi_agent(**multi_agent.parse(multi))
            except ValueError as e:
                raise UsageError(
                    _one_line(e), source=exp.source, key=f"{exp.name}.config.multi_agent"
                ) from None
        if rl_module is None and family is not None and family.default_module is not None:
            rl_module = {"module_class": family.default_module}
        if rl_module is not None:
            cfg.rl_module(rl_module_spec=_module_spec(rl_module, exp))
        cfg.environment(env=exp.env, env_config=env_config)
        if model_config is not None:
            cfg.rl_module(model_config=model_config)
        if connector is not None:
            cfg.env_runners(env_to_module_connector=connector)
        try:
            cfg.update_from_dict(values)
        except Exception as e:  # a value RLlib's setters reject
            raise UsageError(
                f"invalid value: {_one_line(e)}", source=exp.source, key=f"{exp.name}.config"
            ) from None
        if (
            family is not None
            and family.metrics_callbacks is not None
            and not {"callbacks", "callbacks_class"} & set(exp.config)
        ):  # the family's metrics (race/...) unless the file names its own callbacks
            cfg.callbacks(family.metrics_callbacks())
        if curriculum is not None:
            from rllib_asor.rllib.callbacks import add_callbacks

            add_callbacks(cfg, curriculum)
        if exp.asor is None and exp.run == "PPO":  # with_asor's PPO Learner reads the key too
            from rllib_asor.rllib.lean_ppo import drop_bootstrap_rows, drop_enabled

            if drop_enabled(cfg):
                cfg = drop_bootstrap_rows(cfg)
        if exp.asor is None and exp.run in ("SAC", "CQL"):  # with_asor does it for ASOR runs
            from rllib_asor.rllib.fast_sac import FAST_KEY, fast_off_policy

            # The fast off-policy path (docs/results.md, issue 11) unless the file opts out
            # with `learner_config_dict: {fast_off_policy: false}`.
            if (cfg.learner_config_dict or {}).get(FAST_KEY) is not False:
                cfg = fast_off_policy(cfg)
    return cfg


def _curriculum(block: Any, exp: Experiment) -> Any:
    """The callback class for a ``curriculum:`` block (envs whose family has one), or None."""
    if block is None:
        return None
    key = f"{exp.name}.config.curriculum"
    family = family_of(exp.env)
    if family is None or family.curriculum is None:
        allowed = ", ".join(families_with_curriculum())
        raise UsageError(
            f"a curriculum needs an env that supports one; allowed envs: {allowed} "
            f"(got {exp.env!r})",
            source=exp.source,
            key=key,
        )
    try:
        return family.curriculum(block)
    except (TypeError, ValueError) as e:
        raise UsageError(_one_line(e), source=exp.source, key=key) from None


def _module_spec(block: dict[str, Any], exp: Experiment) -> Any:
    """RLModuleSpec for `rl_module: {module_class: ...}`; model_config comes from the config."""
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    from rllib_asor.models import get_module_class

    try:
        return RLModuleSpec(module_class=get_module_class(block["module_class"]))
    except ValueError as e:
        raise UsageError(
            _one_line(e), source=exp.source, key=f"{exp.name}.config.rl_module.module_class"
        ) from None


def _one_line(e: BaseException) -> str:
    return " ".join(str(e).split()) or type(e).__name__


def _check_grids(exp: Experiment) -> None:
    if any(True for _ in grid.find_grids(exp.config.get("multi_agent") or {})):
        raise UsageError(
            "grid_search is not allowed here: allowed fixed policies and policy_mapping_fn",
            source=exp.source,
            key=f"{exp.name}.config.multi_agent",
        )
    for tree, prefix in ((exp.config, "config"), (exp.asor or {}, "config.asor")):
        for path, candidates in grid.find_grids(tree):
            if not isinstance(candidates, list) or not candidates:
                raise UsageError(
                    f"{candidates!r} is invalid: allowed a non-empty list of values",
                    source=exp.source,
                    key=f"{exp.name}.{prefix}.{'.'.join(path)}.grid_search",
                )


def _check_checkpoint_config(exp: Experiment) -> None:
    from ray import tune

    try:
        with _quiet():
            tune.CheckpointConfig(**checkpoint_kwargs(exp))
    except (ValueError, TypeError) as e:
        raise UsageError(
            _one_line(e), source=exp.source, key=f"{exp.name}.checkpoint_config"
        ) from None


def validate_asor(exp: Experiment) -> None:
    """Validate the asor block with AsorConfig for every grid candidate."""
    if exp.asor is None:
        return
    from rllib_asor.asor.config import ALGORITHMS, AsorConfig

    if exp.run not in ALGORITHMS:
        raise UsageError(
            f"ASOR does not support {exp.run!r}; allowed: {', '.join(ALGORITHMS)}",
            source=exp.source,
            key=f"{exp.name}.run",
        )
    points: list[dict[grid.Path, Any]] = [{}]
    for path, candidates in grid.find_grids(exp.asor):
        points += [{path: c} for c in candidates]
    for choice in points:
        try:
            AsorConfig.from_dict(grid.with_candidates(exp.asor, choice))
        except (ValueError, TypeError) as e:
            raise UsageError(
                _one_line(e), source=exp.source, key=f"{exp.name}.config.asor"
            ) from None


def validate_env(exp: Experiment) -> None:
    """The env id must be registered, and the env must build with each `env_config` candidate."""
    import gymnasium as gym

    from rllib_asor.rllib import env_registration as envs

    with _quiet():
        if not envs.env_exists(exp.env):
            raise UsageError(
                f"unknown env id {exp.env!r}; allowed: {envs.known_ids()}",
                source=exp.source,
                key=f"{exp.name}.env",
            )
        if exp.env not in gym.registry and exp.env not in envs.race_creators():
            return  # registered with Tune by someone else: built only on the env runners
        tree = exp.config.get("env_config") or {}
        points: list[dict[grid.Path, Any]] = [{}]
        for path, candidates in grid.find_grids(tree):
            points += [{path: c} for c in candidates[1:]]
        for choice in points:
            env_config = grid.with_candidates(tree, choice)
            try:
                envs.make_env(exp.env, env_config).close()
            except Exception as e:
                raise UsageError(
                    f"{exp.env} cannot be built with {env_config!r}: {_one_line(e)}",
                    source=exp.source,
                    key=f"{exp.name}.config.env_config",
                ) from None


def validate(exp: Experiment) -> Any:
    """Check everything that can be checked before Ray starts; return the first-point config."""
    check_offline_input(exp)
    _check_grids(exp)
    _check_checkpoint_config(exp)
    algorithm_class(exp)
    validate_asor(exp)
    validate_env(exp)
    cfg = None
    points: list[dict[grid.Path, Any]] = [{}]
    for path, candidates in grid.find_grids(exp.config):
        points += [{path: c} for c in candidates[1:]]
    for choice in points:
        candidate = build_algo_config(exp, choice)
        with _quiet():
            try:
                candidate.validate()
            except Exception as e:
                raise UsageError(
                    _one_line(e), source=exp.source, key=f"{exp.name}.config"
                ) from None
        cfg = cfg or candidate
    return cfg


# ---------------------------------------------------------------------------------- Tune
def param_space(exp: Experiment, algo_config: Any | None = None) -> dict[str, Any]:
    """Tune param space: `algo_config.to_dict()` with grids as `tune.grid_search` and `asor`."""
    from ray import tune

    cfg = algo_config if algo_config is not None else build_algo_config(exp)
    space = cfg.to_dict()
    for path, candidates in grid.find_grids(exp.config):
        attr = _attr_name(path[0])
        top = PARAM_SPACE_KEYS.get(attr, attr)
        grid.set_path(space, (top, *path[1:]), tune.grid_search(list(candidates)))
    if exp.asor is not None:
        space["asor"] = grid.to_tune(exp.asor)
    return space


def required_cpus(algo_config: Any) -> float:
    """Logical CPUs one trial needs: main process + env runners + learners, plus the Ray
    Data tasks and actors of an offline run (`offline_data_cpus`)."""
    cls = algo_config.algo_class
    try:
        pgf = cls.default_resource_request(algo_config)
        trial = float(pgf.required_resources.get("CPU", 1))
    except Exception:
        c = algo_config
        trial = 1.0 + c.num_env_runners * c.num_cpus_per_env_runner + max(c.num_learners, 0)
    return trial + offline_data_cpus(algo_config)


def offline_data_cpus(algo_config: Any) -> float:
    """CPUs an offline run's Ray Data pipeline takes outside the trial's own reservation:
    a read task (1) and RLlib's `OfflinePreLearner` actors (`map_batches_kwargs` concurrency,
    default max(2, num_learners), 1 CPU each unless `num_cpus` says otherwise). Without them
    free, reading waits forever (measured on 2 CPUs: "3/2 CPU requested", no progress)."""
    source = getattr(algo_config, "input_", "sampler")
    if not source or source == "sampler":
        return 0.0
    kwargs = dict(getattr(algo_config, "map_batches_kwargs", None) or {})
    concurrency = kwargs.get("concurrency", max(2, algo_config.num_learners))
    if isinstance(concurrency, tuple | list):  # (min, max) actor pool
        concurrency = concurrency[-1]
    return 1.0 + float(concurrency) * float(kwargs.get("num_cpus", 1.0))
