"""Validate: everything about an `Experiment` that can be checked before Ray starts."""

from __future__ import annotations

from typing import Any

from rllib_asor.cli import grid
from rllib_asor.cli.build import algorithm_class, build_algo_config
from rllib_asor.cli.errors import Problems, UsageError, one_line, quiet
from rllib_asor.cli.offline_inputs import check_demonstrations, check_offline_input
from rllib_asor.cli.overrides import checkpoint_kwargs
from rllib_asor.cli.spec import SETTINGS_BLOCKS, Experiment
from rllib_asor.cli.stop_keys import check_stop, require_stop


def _check_grids(exp: Experiment) -> None:
    if any(True for _ in grid.find_grids(exp.config.get("multi_agent") or {})):
        raise UsageError(
            "grid_search is not allowed here: allowed fixed policies and policy_mapping_fn",
            source=exp.source,
            key=f"{exp.name}.config.multi_agent",
        )
    problems = Problems()
    for tree, prefix in ((exp.config, "config"), (exp.asor or {}, "config.asor")):
        for path, candidates in grid.find_grids(tree):
            if not isinstance(candidates, list) or not candidates:
                problems.add(
                    UsageError(
                        f"{candidates!r} is invalid: allowed a non-empty list of values",
                        source=exp.source,
                        key=f"{exp.name}.{prefix}.{'.'.join(path)}.grid_search",
                    )
                )
    problems.raise_any()


def _check_checkpoint_config(exp: Experiment) -> None:
    from ray import tune

    try:
        with quiet():
            tune.CheckpointConfig(**checkpoint_kwargs(exp))
    except (ValueError, TypeError) as e:
        raise UsageError(
            one_line(e), source=exp.source, key=f"{exp.name}.checkpoint_config"
        ) from None


def validate_asor(exp: Experiment) -> None:
    """Validate the asor block with AsorConfig for every grid candidate."""
    if exp.asor is None:
        return
    from rllib_asor.asor.config import ALGORITHMS, AsorConfig
    from rllib_asor.rllib.wiring import supported_run

    if supported_run(exp.run) is None:  # ALGORITHMS or a subclass of one (FastSAC, OSI, ...)
        from rllib_asor.registry.algorithms import ALGORITHMS as OURS

        allowed = [*ALGORITHMS, *(n for n in OURS if n not in ALGORITHMS and supported_run(n))]
        raise UsageError(
            f"ASOR does not support {exp.run!r}; allowed: {', '.join(allowed)}",
            source=exp.source,
            key=f"{exp.name}.run",
        )
    _each_candidate(exp.asor, AsorConfig.from_dict, exp, f"{exp.name}.config.asor")


def _each_candidate(block: dict[str, Any], check: Any, exp: Experiment, key: str) -> None:
    """`check(settings)` for the block's first candidate and each grid value; one line naming
    `key` on the first ValueError/TypeError."""
    points: list[dict[grid.Path, Any]] = [{}]
    for path, candidates in grid.find_grids(block):
        points += [{path: c} for c in candidates]
    for choice in points:
        try:
            check(grid.with_candidates(block, choice))
        except (ValueError, TypeError) as e:
            raise UsageError(one_line(e), source=exp.source, key=key) from None


def validate_blocks(exp: Experiment) -> None:
    """Each block of `SETTINGS_BLOCKS` that names its runs (`escp:`, `maple:`) only with one of
    them, validated by its settings class for every grid candidate (one line per block naming
    the key, the value and what is allowed)."""
    problems = Problems()
    for name, block in SETTINGS_BLOCKS.items():
        settings = exp.config.get(block.key) if block.runs and block.key else None
        if settings is None:
            continue
        key = f"{exp.name}.config.{name}"
        with problems.check():
            if exp.run not in block.runs:
                article = "an" if name[0] in "aeiou" else "a"
                raise UsageError(
                    f"{article} {name}: block needs run: {' or '.join(block.runs)}, "
                    f"not {exp.run!r}",
                    source=exp.source,
                    key=key,
                )
            _each_candidate(settings, block.settings_class().from_dict, exp, key)
    problems.raise_any()


def validate_env(exp: Experiment) -> None:
    """The env must resolve (`registry.env_names`: ids, `module:EnvId`, class paths, old gym
    ids) and build with each `env_config` candidate; an old id is replaced by its new one."""
    from rllib_asor.registry import env_names

    with quiet():
        try:
            ref = env_names.resolve_env(exp.env)
        except ValueError as e:
            raise UsageError(one_line(e), source=exp.source, key=f"{exp.name}.env") from None
        if ref.note:
            exp.warnings.append(f"{exp.source}: {ref.note}")
        plain = ref.module is None and ref.attr is None and ref.spec is None and not ref.tune
        if plain and ref.env_id != exp.env:
            exp.env = ref.env_id
        tree = exp.config.get("env_config") or {}
        points: list[dict[grid.Path, Any]] = [{}]
        for path, candidates in grid.find_grids(tree):
            points += [{path: c} for c in candidates[1:]]
        for choice in points:
            env_config = grid.with_candidates(tree, choice)
            try:
                env = env_names.build_env(ref, env_config)
                space = env.observation_space
                env.close()
            except Exception as e:
                raise UsageError(
                    f"{exp.env} cannot be built with {env_config!r}: {one_line(e)}",
                    source=exp.source,
                    key=f"{exp.name}.config.env_config",
                ) from None
        _flatten_for_the_default_module(exp, space)


def _flatten_for_the_default_module(exp: Experiment, space: Any) -> None:
    """RLlib's default RLModules read Box observations only: for a Discrete, MultiDiscrete,
    Dict or Tuple space (and no module or connector of the file's own) add RLlib's
    `FlattenObservations` (one-hot for discrete parts), as RLlib's own examples do."""
    import gymnasium as gym

    from rllib_asor.cli import legacy
    from rllib_asor.registry.families import family_of

    family = family_of(exp.env)
    if (
        isinstance(space, gym.spaces.Box)
        or not isinstance(space, gym.spaces.Space)
        or {"rl_module", "env_to_module_connector"} & set(exp.config)
        or family is not None and family.default_module is not None
    ):
        return
    exp.config["env_to_module_connector"] = legacy.flatten_observations_connector
    exp.warnings.append(
        f"{exp.source}: observation space {space}: added RLlib's FlattenObservations connector "
        "(one-hot for discrete parts): the default RLModule reads Box observations only"
    )


def check_file(exp: Experiment, evaluation: bool = False) -> None:
    """The file's own `config:` and `stop:` as written, before `--test`, `--stop` or
    `--num-env-runners` replace any of them: what the real run would refuse is refused here
    too. Leaves `exp` as it was, but for numbers written as text (read as numbers).
    `evaluation`: the caller turns evaluation on (`evaluation/...` stop keys are reported).
    A UsageError names every problem found (one line each)."""
    problems = Problems()
    _check_configs(exp, problems, _check_blocks(exp, problems), evaluation)
    problems.raise_any()


def _check_blocks(exp: Experiment, problems: Problems) -> bool:
    """The grids, checkpoint settings, algorithm and our blocks (`asor:`, `escp:`, ...), each
    problem kept in `problems`; whether the configs can be built (grids, algorithm and blocks
    well formed: building them would only say the same again)."""
    checks = (_check_grids, _check_checkpoint_config, algorithm_class, validate_asor,
              validate_blocks)  # fmt: skip
    passed = {check: problems.passed(check, exp) for check in checks}
    return passed[_check_grids] and passed[algorithm_class] and passed[validate_blocks]


def _check_configs(
    exp: Experiment, problems: Problems, buildable: bool, evaluation: bool = False
) -> Any:
    """`_check_config_points`, or where no config can be built (not `buildable`) the stop keys
    as far as the algorithm tells; each problem kept in `problems`; the first point's config
    (None: none built)."""
    if not buildable:
        problems.passed(_check_stop_keys, exp, None, evaluation)
        return None
    with problems.check():
        return _check_config_points(exp, evaluation)
    return None


def _check_config_points(exp: Experiment, evaluation: bool = False) -> Any:
    """Build and validate the AlgorithmConfig of every grid point and check the stop keys
    (against the algorithm's defaults when no point builds); the first point's config."""
    problems = Problems()
    cfg = None
    points: list[dict[grid.Path, Any]] = [{}]
    for path, candidates in grid.find_grids(exp.config):
        points += [{path: c} for c in candidates[1:]]
    for choice in points:
        with problems.check():
            candidate = build_algo_config(exp, choice)
            with quiet():
                try:
                    candidate.validate()
                except Exception as e:
                    raise UsageError(
                        one_line(e), source=exp.source, key=f"{exp.name}.config"
                    ) from None
            cfg = cfg or candidate
    problems.passed(_check_stop_keys, exp, cfg, evaluation)
    problems.raise_any()
    return cfg


def _check_stop_keys(exp: Experiment, cfg: Any, evaluation: bool = False) -> None:
    """The stop keys against `cfg`, or (None: no config could be built) against the
    algorithm's defaults and the file's `evaluation_interval`."""
    if cfg is None:
        with quiet():
            cfg = algorithm_class(exp).get_default_config()
        evaluation = evaluation or bool(exp.config.get("evaluation_interval"))
    check_stop(exp, cfg, evaluation)


def validate(exp: Experiment) -> Any:
    """Check everything that can be checked before Ray starts, the stop that `--test`/`--stop`
    may have supplied included (a UsageError names every problem, one line each); return the
    first-point config."""
    problems = Problems()
    problems.passed(check_offline_input, exp)
    problems.passed(check_demonstrations, exp)
    buildable = _check_blocks(exp, problems)
    problems.passed(validate_env, exp)  # before the configs: it may rename the env
    cfg = _check_configs(exp, problems, buildable)
    problems.passed(require_stop, exp)
    problems.raise_any()
    _check_env_runner(exp, cfg)
    return cfg


def _check_env_runner(exp: Experiment, cfg: Any) -> None:
    """Build one env runner here, as each remote one will be built (env, connectors, RLModule),
    so that what would kill them fails now, in one line, and not as RLlib's IndexError later."""
    if cfg.input_ != "sampler":
        return  # offline data: no env runners sample
    from ray.rllib.env.multi_agent_env_runner import MultiAgentEnvRunner
    from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner

    from rllib_asor.registry import env_names

    default = MultiAgentEnvRunner if cfg.is_multi_agent else SingleAgentEnvRunner
    local = cfg.copy(copy_frozen=False).env_runners(num_envs_per_env_runner=1)
    with quiet():
        try:
            env_names.register_env(exp.env)
            runner = (cfg.env_runner_cls or default)(config=local)
        except Exception as e:
            raise UsageError(
                f"an env runner cannot be built for {exp.env}: {one_line(e)}",
                source=exp.source,
                key=f"{exp.name}.config",
            ) from None
        runner.stop()
