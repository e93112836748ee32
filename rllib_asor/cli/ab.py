"""`rllib ab FILE.yaml --seeds N [--vs FILE2.yaml]`: does the file's `asor:` block help?

One Tune run trains the file's experiment with and without its `asor:` block (or against the
experiment of `--vs FILE2.yaml`) on seeds 0..N-1, both arms with the same seeds and, without
`--vs`, the same algorithm in every other respect (module, replay, critics, update rhythm:
checked before the run, `arm_differences`), greedy
evaluation during training (RLlib's evaluation env runners, returns per ``dynamics_id``), then
every final checkpoint is evaluated on the same episodes (`evaluation.json` per trial) and
`rllib compare` prints the paired result; tables and figures go to ``<experiment>/ab/``.
Rerunning the same command resumes: finished trials and evaluations are kept, seeds the folder
lacks are run, and a file whose settings changed is refused (`rllib_asor.cli.manifest`).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any

from rllib_asor.cli.errors import Problems, UsageError
from rllib_asor.cli.evaluate import EVAL_SEED  # the env seed of the final evaluation

DEFAULT_STORAGE = "~/ray_results"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `rllib ab`."""
    parser.add_argument("file", metavar="FILE.yaml", help="a YAML file with one experiment")
    parser.add_argument("--seeds", type=int, required=True, metavar="N", help="paired seeds 0..N-1")
    parser.add_argument(
        "--vs",
        metavar="FILE2.yaml",
        help="baseline: this file's experiment (default: FILE without its asor: block)",
    )
    parser.add_argument(
        "--episodes", type=int, default=20, help="final evaluation episodes per checkpoint (20)"
    )
    parser.add_argument(
        "--eval-interval",
        type=int,
        metavar="N",
        help="evaluate every N iterations during training (default: the file's "
        "evaluation_interval, else 5 or the stop's training_iteration if fewer; --test: 1)",
    )
    parser.add_argument(
        "--name", help="experiment folder (default: NAME-ab of the file, NAME-ab-test with --test)"
    )
    parser.add_argument(
        "--fresh",
        action="store_true",
        help="start over: the folder of this name is renamed NAME.replaced-TIME",
    )
    parser.add_argument("--storage-path", help=f"results root (default {DEFAULT_STORAGE})")
    parser.add_argument("--test", action="store_true", help="tiny run, as `rllib train --test`")
    parser.add_argument("--num-env-runners", type=int, help="override num_env_runners")
    parser.add_argument(
        "--stop", action="append", metavar="KEY=VALUE", help="stop criterion (repeatable)"
    )


def _one(path: str, flag: str) -> Any:
    from rllib_asor.cli import experiment

    exps = experiment.load_file(path)
    if len(exps) != 1:
        raise UsageError(f"holds {len(exps)} experiments; allowed: one", source=path, key=flag)
    exp = exps[0]
    from rllib_asor.cli import grid

    if any(grid.find_grids(exp.config)) or any(grid.find_grids(exp.asor or {})):
        raise UsageError(
            "has a grid_search; rllib ab compares two settings (sweep with 'rllib train', then "
            "'rllib compare')",
            source=path,
        )
    if exp.num_samples != 1:
        raise UsageError("num_samples must be 1: rllib ab runs one trial per seed", source=path)
    return exp


def arms(args: argparse.Namespace) -> list[tuple[str, Any]]:
    """[(baseline name, experiment), (treatment name, experiment)] from the files."""
    import copy

    treat = _one(args.file, "FILE")
    if args.vs:
        base = _one(args.vs, "--vs")
        if base.run != treat.run or base.env != treat.env:
            raise UsageError(
                f"runs {base.run} on {base.env}, {args.file} runs {treat.run} on {treat.env}; "
                "allowed: the same run and env (paired seeds)",
                source=args.vs,
            )
        names = [Path(args.vs).stem, Path(args.file).stem]
        if names[0] == names[1]:
            names = [f"{names[0]} (--vs)", names[1]]
        return [(names[0], base), (names[1], treat)]
    if treat.asor is None:
        raise UsageError(
            "has no asor: block, nothing to compare; add one or give --vs FILE2.yaml",
            source=args.file,
        )
    base = copy.deepcopy(treat)
    base.asor = None
    _same_replay_path(base, treat)
    return [(treat.run, base), (f"{treat.run}+ASOR", treat)]


def _same_replay_path(base: Any, treat: Any) -> None:
    """A `run: SAC`/`CQL` file whose asor block trains per-dynamics RND keeps RLlib's replay
    (cli/build.py): its baseline, which has no asor block, must keep it too."""
    from rllib_asor.algorithms.sac.fast import FAST_KEY
    from rllib_asor.cli.build import per_dynamics_rnd

    if treat.run in ("SAC", "CQL") and per_dynamics_rnd(treat):
        for exp in (base, treat):
            lcd = exp.config.get("learner_config_dict")
            exp.config["learner_config_dict"] = {**(lcd or {}), FAST_KEY: False}


def arm_check(named: list[tuple[str, Any, Any]], vs: bool) -> str | None:
    """What besides ASOR tells the arms apart: None when the baseline has an asor block too or
    the treatment none (nothing to check), else a line to print. Without `--vs` the arms come
    from one file and must differ only in ASOR: UsageError otherwise."""
    from rllib_asor.rllib.wiring import arm_differences, with_asor

    (_, base_exp, base), (_, treat_exp, treat) = named
    if base_exp.asor is not None or treat_exp.asor is None:
        return None
    try:
        differences = arm_differences(base, with_asor(treat, **treat_exp.asor))
    except ValueError as e:
        raise UsageError(
            str(e), source=treat_exp.source, key=f"{treat_exp.name}.config.asor"
        ) from None
    if not differences:
        return "rllib ab: the arms differ only in ASOR (same module, replay, critics and rhythm)"
    if not vs:
        raise UsageError(
            f"the arms would differ in more than ASOR: {', '.join(differences)}; allowed: none",
            source=treat_exp.source,
        )
    return f"rllib ab: besides ASOR, the arms differ in: {', '.join(differences)}"


def _prepare(exp: Any, args: argparse.Namespace) -> Any:
    """Overrides, evaluation settings and the seed grid on `exp`; its validated config with
    the per-dynamics returns callback."""
    from rllib_asor.algorithms.common.callbacks import add_callbacks
    from rllib_asor.cli import experiment
    from rllib_asor.evaluation.dynamics import DynamicsReturnsCallback

    problems = Problems()  # every problem of the file at once, as `rllib train` reports them
    with problems.check():
        experiment.check_file(exp, evaluation=True)  # as written, before --test/--stop
    with problems.check():
        experiment.apply_overrides(
            exp,
            test=args.test,
            num_env_runners=args.num_env_runners,
            stop=experiment.parse_stop_flags(args.stop),
        )
        cfg = exp.config
        iterations = exp.stop.get("training_iteration")
        default = 1 if args.test else min(5, int(iterations)) if iterations else 5
        cfg["evaluation_interval"] = (
            args.eval_interval or cfg.get("evaluation_interval") or default
        )
        cfg.setdefault("evaluation_duration", 2 if args.test else 10)
        cfg["evaluation_config"] = {"explore": False, **(cfg.get("evaluation_config") or {})}
        cfg["seed"] = 0
        algo_config = experiment.validate(exp)
    problems.raise_any()
    add_callbacks(algo_config, DynamicsReturnsCallback)
    return algo_config


def prepared_arms(args: argparse.Namespace) -> list[tuple[str, Any, Any]]:
    """[(name, experiment, validated config)] of the baseline and the treatment."""
    (base_name, base), (treat_name, treat) = arms(args)
    treat_config = _prepare(treat, args)
    if not args.vs and "input" in treat.config:  # --test's stand-in datasets: one set for both
        base.config["input"] = treat.config["input"]
    return [(base_name, base, _prepare(base, args)), (treat_name, treat, treat_config)]


def param_space(
    named: list[tuple[str, Any, Any]], seeds: list[int], smoke: bool = False
) -> dict[str, Any]:
    """One Tune space for both arms: a grid over (arm, seed); every key whose value differs
    between the arms is resolved from the trial's arm (`tune.sample_from`)."""
    from ray import tune

    from rllib_asor.cli import experiment
    from rllib_asor.report.grouping import ARM_KEY
    from rllib_asor.report.results import RUN_KEY, SMOKE_KEY

    spaces = {}
    for name, exp, cfg in named:
        space = experiment.param_space(exp, cfg)
        space.setdefault("asor", None)
        space[RUN_KEY] = exp.run
        spaces[name] = space
    first = next(iter(spaces.values()))
    keys = set().union(*spaces.values())
    out = dict(first)
    for key in sorted(keys):
        values = [s.get(key) for s in spaces.values()]
        if any(v != values[0] for v in values[1:]) or key not in first:
            out[key] = tune.sample_from(lambda config, key=key: spaces[config[ARM_KEY]].get(key))
    out[ARM_KEY] = tune.grid_search(list(spaces))
    out["seed"] = tune.grid_search(list(seeds))
    if smoke:
        out[SMOKE_KEY] = True  # `rllib compare` gives smoke runs no verdict
    return out


def trainable_for(named: list[tuple[str, Any, Any]], source: str) -> Any:
    """One Algorithm class for both arms: ours, where an asor block of None is the plain
    algorithm; RLlib's when neither arm runs ASOR (`--vs` between two plain files)."""
    from rllib_asor.cli import experiment
    from rllib_asor.rllib.trainable import asor_trainable

    exp = named[-1][1]
    if not any(e.asor is not None for _, e, _ in named):
        return experiment.algorithm_class(exp)
    try:
        return asor_trainable(exp.run)
    except ValueError as e:
        raise UsageError(str(e), source=source) from None


def seed_batches(record: dict[str, Any], seeds: int) -> list[dict[str, Any]]:
    """The Tune experiments of the folder (``{"dir", "seeds"}``; the first one is the folder
    itself), with a new one for the seeds 0..`seeds`-1 that none holds yet (added to `record`)."""
    batches = record.setdefault("seeds", [])
    held = {s for b in batches for s in b["seeds"]}
    new = [s for s in range(seeds) if s not in held]
    if new:
        name = "" if not batches else f"seeds-{new[0]}-{new[-1]}"
        batches.append({"dir": name, "seeds": new})
    return batches


def fit(
    args: argparse.Namespace,
    named: list[tuple[str, Any, Any]],
    path: str,
    seeds: list[int],
    trainable: Any,
) -> Any:
    """Run (or resume) the Tune experiment of `seeds` at `path`; its ResultGrid."""
    from ray import tune

    from rllib_asor.cli import experiment
    from rllib_asor.cli.progress import LineReporter

    exp = named[-1][1]
    space = param_space(named, seeds, smoke=args.test)
    if tune.Tuner.can_restore(path):
        print(f"rllib ab: resuming {path} (finished trials are kept)", flush=True)
        tuner = tune.Tuner.restore(
            path, trainable, param_space=space, resume_unfinished=True, resume_errored=True
        )
    else:
        tuner = tune.Tuner(
            trainable,
            param_space=space,
            run_config=tune.RunConfig(
                name=os.path.basename(path),
                storage_path=os.path.dirname(path),
                stop=exp.stop or None,
                checkpoint_config=tune.CheckpointConfig(**experiment.checkpoint_kwargs(exp)),
                progress_reporter=LineReporter(exp.stop),
                verbose=1,
            ),
        )
    return tuner.fit()


def evaluate_trials(results: Any, episodes: int) -> list[str]:
    """Write `evaluation.json` next to each trial's final checkpoint (kept when it is already
    for that checkpoint); the problems, one line each."""
    from rllib_asor.cli.evaluate import evaluate
    from rllib_asor.report.files import atomic_write
    from rllib_asor.report.scores import EVAL_FILE

    problems = []
    for result in results:
        if result.error or result.checkpoint is None:
            problems.append(f"{result.path}: no final checkpoint (errored?), not evaluated")
            continue
        out = Path(result.path) / EVAL_FILE
        ckpt = result.checkpoint.path
        if out.is_file():
            try:
                held = json.loads(out.read_text())
                if held.get("checkpoint") == ckpt and held.get("episodes") == episodes:
                    continue
            except (OSError, json.JSONDecodeError):
                pass
        stats = evaluate(ckpt, episodes, seed=EVAL_SEED, evaluation_config=True)
        atomic_write(out, (json.dumps(stats) + "\n").encode())
        print(
            f"rllib ab: evaluated {os.path.basename(result.path)}: "
            f"return {stats['return_mean']:.4g} over {stats['episodes']} episodes",
            flush=True,
        )
    return problems


def write_outputs(path: str, baseline: str, trials: list[str] | None = None) -> str:
    """Compare the trials at `path` (only the trial folders `trials` when given); write
    compare.md/json and the figures to `path/ab`; the text printed."""
    from rllib_asor.report.compare import compare, render_text
    from rllib_asor.report.files import atomic_write
    from rllib_asor.report.plots import plot_curves, plot_dynamics, plot_paired
    from rllib_asor.report.scores import EVAL_KEY, TRAIN_KEY

    comp = compare(trials or [path], baseline=baseline)
    out = Path(path) / "ab"
    out.mkdir(exist_ok=True)
    text = render_text(comp)
    atomic_write(out / "compare.md", text.encode())
    rows = [r.to_json() for r in comp.results]
    atomic_write(out / "compare.json", (json.dumps(rows, default=str, indent=1) + "\n").encode())
    groups = [(g.label, g.trials) for g in comp.groups]
    x = "num_env_steps_sampled_lifetime"
    figures = []
    for key, name in ((TRAIN_KEY, "curves_training.png"), (EVAL_KEY, "curves_evaluation.png")):
        if all(t.has(key) for _, ts in groups for t in ts):
            plot_curves(groups, key, x, out / name, key, comp.notes.append)
            figures.append(name)
    for r in comp.results:
        if r.dynamics is None:
            plot_paired(r, out / "paired.png")
            figures.append("paired.png")
            dyn = [d for d in comp.results if d.dynamics is not None and d.treatment == r.treatment]
            if dyn:
                plot_dynamics(dyn, out / "dynamics.png")
                figures.append("dynamics.png")
            break
    return text + f"\nwritten: {out}/compare.md, compare.json, {', '.join(figures)}\n"


def run(args: argparse.Namespace) -> int:
    """`rllib ab`: 0 when every trial finished and was evaluated, 1 otherwise, 2 bad input."""
    from rllib_asor.cli import manifest
    from rllib_asor.cli.cluster import check_local_gpus, start_ray
    from rllib_asor.cli.experiment import required_cpus
    from rllib_asor.registry import env_names

    if args.seeds < 2:
        raise UsageError(f"{args.seeds} is invalid: allowed an integer >= 2", key="--seeds")
    if args.episodes < 1:
        raise UsageError(f"{args.episodes} is invalid: allowed an integer >= 1", key="--episodes")
    named = prepared_arms(args)
    for _, e, c in named:
        check_local_gpus(e, c)  # `rllib ab` trains on a local Ray
    check = arm_check(named, vs=bool(args.vs))
    trainable = trainable_for(named, args.file)
    exp = named[-1][1]
    root = os.path.abspath(
        os.path.expanduser(args.storage_path or exp.storage_path or DEFAULT_STORAGE)
    )
    smoke = manifest.SMOKE_SUFFIX if args.test else ""
    path = os.path.join(root, args.name or f"{exp.name}-ab{smoke}")
    wanted = {"command": "ab", "arms": {n: manifest.describe(e, args.test) for n, e, _ in named}}
    record, _ = manifest.prepare(path, wanted, fresh=args.fresh, smoke=args.test)
    asked = list(range(args.seeds))
    batches = seed_batches(record, args.seeds)
    manifest.write(path, record)  # before Tune starts: an interrupted run is still recorded
    for _, e, _ in named:
        for warning in dict.fromkeys(e.warnings):
            print(f"rllib: warning: {warning}", file=sys.stderr)
    held = sorted({s for b in batches for s in b["seeds"]} - set(asked))
    print(
        f"rllib ab: {named[1][0]} vs {named[0][0]} on {exp.env}, seeds 0-{args.seeds - 1} "
        f"({2 * args.seeds} trials), results in {path}"
        + (f" (it also holds seeds {_ranges(held)}, not compared)" if held else ""),
        flush=True,
    )
    if args.test:
        print("rllib ab: --test is a smoke run: too short to learn, no verdict", flush=True)
    if check:
        print(check, flush=True)
    os.environ["RAY_AIR_NEW_OUTPUT"] = "0"
    started = start_ray(None, max(required_cpus(c) for _, _, c in named))
    env_names.register_env(exp.env)
    try:
        results = []
        for batch in batches:
            seeds = [s for s in batch["seeds"] if s in asked]
            if seeds:
                where = os.path.join(path, batch["dir"]) if batch["dir"] else path
                grid = fit(args, named, where, batch["seeds"], trainable)
                results += [r for r in grid if _seed_of(r) in seeds]
        problems = evaluate_trials(results, args.episodes)
    finally:
        if started:
            import ray

            ray.shutdown()
    for p in problems:
        print(f"rllib ab: {p}", file=sys.stderr)
    try:
        print(write_outputs(path, named[0][0], [str(r.path) for r in results]), end="")
    except ValueError as e:
        print(f"rllib ab: error: {e}", file=sys.stderr)
        return 1
    return 1 if problems else 0


def _seed_of(result: Any) -> Any:
    return (result.config or {}).get("seed")


def _ranges(seeds: list[int]) -> str:
    return ", ".join(str(s) for s in seeds)
