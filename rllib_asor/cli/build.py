"""Build: an `Experiment` (one grid point) into an RLlib AlgorithmConfig, and the Tune param space."""

from __future__ import annotations

import difflib
from typing import Any

from rllib_asor import ray_compat as compat
from rllib_asor.cli import grid, multi_agent
from rllib_asor.cli.errors import Problems, UsageError, one_line, quiet
from rllib_asor.cli.spec import Experiment
from rllib_asor.cli.value_types import check_config_values
from rllib_asor.registry.families import families_with_curriculum, family_of

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
    **compat.TO_DICT_KEYS,
    "lambda_": "lambda",
    "input_": "input",
    "framework_str": "framework",
    "callbacks_class": "callbacks",
    "create_env_on_local_worker": "create_env_on_driver",
    "custom_evaluation_function": "custom_eval_function",
}


PPO_ONLY_LEARNER_KEYS = ("overlap_sampling", "drop_bootstrap_rows")
"""`learner_config_dict` switches of ours that only PPO reads (docs/speed.md)."""


def algorithm_class(exp: Experiment) -> type:
    """The RLlib Algorithm class for `exp.run` (UsageError if unknown)."""
    from ray.tune.registry import get_trainable_cls

    from rllib_asor.registry.algorithms import register_algorithms, run_names

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
        from rllib_asor.algorithms.ppo.overlap import OverlappedPPO

        return OverlappedPPO  # PPO whose env runners sample during the update
    try:
        with quiet():
            register_algorithms()  # ours: MAPLE, MOPO, ESCP, FastSAC, ...
            cls = get_trainable_cls(exp.run)
    except Exception:
        raise UsageError(
            f"unknown algorithm {exp.run!r}; allowed: {', '.join(run_names())}",
            source=exp.source,
            key=f"{exp.name}.run",
        ) from None
    offline = getattr(cls, "offline_variant", None)  # SOIL: MARWIL-based when given `input:`
    return offline if offline is not None and exp.config.get("input") else cls


def attr_name(key: str) -> str:
    return compat.config_attr_name(key)


def check_key(default_cfg: Any, key: str, exp: Experiment) -> None:
    if key in SPECIAL_CONFIG_KEYS:
        return
    attr = attr_name(key)
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
    if getattr(default_cfg, attr, None) == compat.deprecated_value():
        raise UsageError(
            f"is deprecated and has no effect on RLlib's new API stack ({algo})",
            source=exp.source,
            key=where,
        )


def check_n_step(exp: Experiment, default_cfg: Any) -> None:
    """`n_step` (DQN, SAC and their kin) needs fragments at least that long: RLlib's own check
    fails with "'int' object is not subscriptable" (its message indexes an int `n_step`). Fixed
    values were raised as old RLlib did (`legacy.translate_config`); a grid is refused here."""
    if not hasattr(default_cfg, "n_step") or "n_step" not in exp.config:
        return
    for n_step in _candidates(exp.config["n_step"]):
        for fragment in _candidates(exp.config.get("rollout_fragment_length", "auto")):
            longest = n_step[-1] if isinstance(n_step, list | tuple) and n_step else n_step
            if (
                isinstance(fragment, int)
                and isinstance(longest, int)
                and not isinstance(fragment, bool)
                and fragment < longest
            ):
                raise UsageError(
                    f"n_step: {n_step!r} needs rollout_fragment_length >= {longest}, got "
                    f"rollout_fragment_length: {fragment}; allowed: rollout_fragment_length: auto "
                    f"or an integer >= {longest}, or n_step <= {fragment}",
                    source=exp.source,
                    key=f"{exp.name}.config.n_step",
                )


def _candidates(value: Any) -> list[Any]:
    """A value's grid candidates, or the value alone."""
    return list(value["grid_search"]) if grid.is_grid(value) else [value]


def build_algo_config(exp: Experiment, choice: dict[grid.Path, Any] | None = None) -> Any:
    """AlgorithmConfig for one grid point (default: first candidate of every grid)."""
    cls = algorithm_class(exp)
    with quiet():
        cfg = cls.get_default_config()
        problems = Problems()  # every key's problem at once
        for key in exp.config:
            with problems.check():
                check_key(cfg, key, exp)
        with problems.check():
            check_config_values(exp, cfg, attr_name)
        with problems.check():
            check_n_step(exp, cfg)
        problems.raise_any()
        values = grid.with_candidates(exp.config, choice)
        family = family_of(exp.env)
        if family is not None:
            values = {**family.config_defaults, **values}
        model_config = values.pop("model_config", None)
        env_config = values.pop("env_config", None) or {}
        if family is not None:
            env_config = {**family.env_config_defaults, **env_config}
        connector = values.pop("env_to_module_connector", None)
        rl_module = values.pop("rl_module", None)
        multi = values.pop("multi_agent", None)
        curriculum = _curriculum(values.pop("curriculum", None), exp)
        if multi is not None:
            try:
                cfg.multi_agent(**multi_agent.parse(multi))
            except ValueError as e:
                raise UsageError(
                    one_line(e), source=exp.source, key=f"{exp.name}.config.multi_agent"
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
                f"invalid value: {one_line(e)}", source=exp.source, key=f"{exp.name}.config"
            ) from None
        if (
            family is not None
            and family.metrics_callbacks is not None
            and not {"callbacks", "callbacks_class"} & set(exp.config)
        ):  # the family's metrics (race/...) unless the file names its own callbacks
            cfg.callbacks(family.metrics_callbacks())
        from rllib_asor.algorithms.common.callbacks import add_callbacks

        if curriculum is not None:
            add_callbacks(cfg, curriculum)
        if exp.asor is None:  # with_asor's own metrics callback drops them for ASOR runs
            from rllib_asor.rllib.callbacks import DropNaNLearnerStatsCallback

            add_callbacks(cfg, DropNaNLearnerStatsCallback)
        if exp.asor is None and exp.run == "PPO":  # with_asor's PPO Learner reads the key too
            from rllib_asor.algorithms.ppo.lean import drop_bootstrap_rows, drop_enabled

            if drop_enabled(cfg):
                cfg = drop_bootstrap_rows(cfg)
        if exp.run in FAST_RUNS:
            cfg = _fast_path(cfg, exp)
    return cfg


FAST_RUNS = ("SAC", "CQL", "FastSAC")
"""Runs whose files go on the fast off-policy path (docs/speed.md), with and without ASOR."""
_said_fast: set[str] = set()


def _fast_path(cfg: Any, exp: Experiment) -> Any:
    """`run: FastSAC` on the fast off-policy path; `run: SAC` / `run: CQL` too unless the file
    opts out with `learner_config_dict: {fast_off_policy: false}` or its asor block trains
    per-dynamics RND. Both arms of a comparison get the same path (`with_asor` never changes
    it); a `run: SAC`/`CQL` file says which once."""
    from rllib_asor.algorithms.sac.fast import FAST_KEY, FLAT_STORAGE, fast_off_policy

    per_dynamics = per_dynamics_rnd(exp)
    if exp.run == "FastSAC":
        if per_dynamics:
            raise UsageError(
                "rnd_per_dynamics needs each step's dynamics id, which FastSAC's flat replay "
                "buffer does not keep; allowed: another proxy, or run: SAC with "
                f"learner_config_dict: {{{FAST_KEY}: false}}",
                source=exp.source,
                key=f"{exp.name}.config.asor.proxy",
            )
        return fast_off_policy(cfg)
    if (cfg.learner_config_dict or {}).get(FAST_KEY) is False:
        return cfg
    if per_dynamics:
        _say_once(
            exp.run,
            f"run: {exp.run} keeps RLlib's own replay and critics: the asor block's "
            "rnd_per_dynamics needs each step's dynamics id, which the fast path's flat buffer "
            "does not keep",
        )
        return cfg
    fast = fast_off_policy(cfg)
    if exp.run == "SAC" and (fast.replay_buffer_config or {}).get("storage") != FLAT_STORAGE:
        _say_once(
            exp.run,
            f"run: SAC gets the fast path's critics only (docs/speed.md): with n_step "
            f"{fast.n_step}, {(fast.replay_buffer_config or {}).get('type')} replay"
            f"{' and several agents' if fast.is_multi_agent else ''} it keeps RLlib's replay "
            f"and Learner; learner_config_dict: {{{FAST_KEY}: false}} gives RLlib's own SAC",
        )
        return fast
    _say_once(
        exp.run,
        f"run: {exp.run} runs on the fast off-policy path (docs/speed.md), with and without "
        f"ASOR; learner_config_dict: {{{FAST_KEY}: false}} gives RLlib's own {exp.run}",
    )
    return fast


def _say_once(run: str, note: str) -> None:
    import sys

    if run not in _said_fast:
        _said_fast.add(run)
        print(f"rllib: note: {note}", file=sys.stderr)


def per_dynamics_rnd(exp: Experiment) -> bool:
    """Whether a candidate of the file's asor block trains per-dynamics RND (it reads each
    step's dynamics id)."""
    if exp.asor is None:
        return False
    from rllib_asor.asor.config import AsorConfig

    points: list[dict[grid.Path, Any]] = [{}]
    for path, candidates in grid.find_grids(exp.asor):
        points += [{path: c} for c in candidates]
    for choice in points:
        try:
            asor = AsorConfig.from_dict(grid.with_candidates(exp.asor, choice))
        except (ValueError, TypeError):
            continue  # validate_asor names it
        if asor.needs_proxy and asor.proxy == "rnd_per_dynamics":
            return True
    return False


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
        raise UsageError(one_line(e), source=exp.source, key=key) from None


def _module_spec(block: dict[str, Any], exp: Experiment) -> Any:
    """RLModuleSpec for `rl_module: {module_class: ...}`; model_config comes from the config."""
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    from rllib_asor.registry.models import get_module_class

    try:
        return RLModuleSpec(module_class=get_module_class(block["module_class"]))
    except ValueError as e:
        raise UsageError(
            one_line(e), source=exp.source, key=f"{exp.name}.config.rl_module.module_class"
        ) from None


def param_space(exp: Experiment, algo_config: Any | None = None) -> dict[str, Any]:
    """Tune param space: `algo_config.to_dict()` with grids as `tune.grid_search` and `asor`."""
    from ray import tune

    cfg = algo_config if algo_config is not None else build_algo_config(exp)
    space = cfg.to_dict()
    for path, candidates in grid.find_grids(exp.config):
        attr = attr_name(path[0])
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


def required_gpus(algo_config: Any) -> float:
    """GPUs one trial asks Ray for: its Learners' (`num_gpus_per_learner`, the local Learner
    with `num_learners: 0`) and its env runners' (`num_gpus_per_env_runner`)."""
    c = algo_config
    try:
        return float(c.algo_class.default_resource_request(c).required_resources.get("GPU", 0))
    except Exception:
        learners = max(c.num_learners, 1) * (c.num_gpus_per_learner or 0)
        return learners + c.num_env_runners * (c.num_gpus_per_env_runner or 0)


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
