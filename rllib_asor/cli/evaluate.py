"""`rllib evaluate CHECKPOINT`: run N episodes with a trained policy on the checkpoint's env.

The algorithm is restored with `Algorithm.from_checkpoint(path, config=...)` using the
checkpoint's own config, changed only to sample locally (no remote env runners, one env);
episodes come from the local env runner, so the same env-to-module connectors (filters,
one-hot, ...) that ran in training run here too. Their statistics are
`rllib_asor.evaluation.summary`'s.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import sys
from typing import Any

from rllib_asor.cli import quiet
from rllib_asor.cli.errors import UsageError, one_line

CHECKPOINT_MARKER = "rllib_checkpoint.json"
CTOR_FILE = "class_and_ctor_args.pkl"
EVAL_SEED = 1_000_000
"""Default env seed of the evaluation: `rllib ab`'s, so that `rllib evaluate` reproduces the
returns `rllib ab` wrote (with `--evaluation-config`, which `rllib ab` uses too)."""


BEST_BY = "return_mean"
RETURN_KEYS = ("return_mean", "return_min", "return_max")
"""What `--best-by` may name besides the env's episode metrics."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `rllib evaluate`."""
    parser.add_argument(
        "checkpoint",
        help="checkpoint dir, or a trial dir (its newest checkpoint), or an experiment dir "
        "(the newest checkpoint of every trial)",
    )
    parser.add_argument("--episodes", type=int, default=10, help="episodes to run (default 10)")
    parser.add_argument(
        "--explore",
        action="store_true",
        help="sample actions from the policy (default: deterministic)",
    )
    parser.add_argument(
        "--seed",
        type=int,
        default=EVAL_SEED,
        help=f"seed of the evaluation env (default {EVAL_SEED}, the seed rllib ab evaluates with)",
    )
    parser.add_argument(
        "--evaluation-config",
        action="store_true",
        help="run the env as the config's evaluation_config sets it (e.g. unseen dynamics)",
    )
    parser.add_argument(
        "--all-checkpoints",
        action="store_true",
        help="evaluate every checkpoint of every trial below the folder, oldest first, and "
        "name each trial's best by --best-by (e.g. to find the peak of a run that declined)",
    )
    parser.add_argument(
        "--best-by",
        default=BEST_BY,
        metavar="NAME",
        help=f"with --all-checkpoints: what 'best' maximises: {BEST_BY} (default), return_min, "
        "or an env metric the episodes report (the race's success, ...)",
    )
    parser.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object on stdout (a list of them for several trials)",
    )


def _checkpoints_below(path: str) -> list[str]:
    """Every `checkpoint_*` directory with RLlib's marker file below `path` (unordered)."""
    found = []
    for root, dirs, files in os.walk(path, followlinks=True):
        if CHECKPOINT_MARKER in files and os.path.basename(root).startswith("checkpoint_"):
            found.append(root)
            dirs.clear()
    return found


def _newest(checkpoints: list[str]) -> str:
    return max(checkpoints, key=lambda p: (os.path.getmtime(p), p))


def find_checkpoint(path: str) -> str:
    """`path` itself if it is an RLlib checkpoint, else the newest checkpoint below it."""
    path = os.path.abspath(os.path.expanduser(path))
    if not os.path.exists(path):
        raise UsageError("not found; allowed: an RLlib checkpoint directory", source=path)
    if os.path.isfile(os.path.join(path, CHECKPOINT_MARKER)):
        return path
    found = _checkpoints_below(path)
    if not found:
        raise UsageError(
            "no RLlib checkpoint in this directory; allowed: a checkpoint_NNNNNN "
            "directory written by 'rllib train'",
            source=path,
        )
    return _newest(found)


def trial_checkpoints(path: str) -> list[str]:
    """The newest checkpoint of every trial below `path` (a trial = a checkpoint's parent);
    `[path]` for a checkpoint itself. UsageError when there is none."""
    path = os.path.abspath(os.path.expanduser(path))
    if os.path.isdir(path) and not os.path.isfile(os.path.join(path, CHECKPOINT_MARKER)):
        trials: dict[str, list[str]] = {}
        for checkpoint in _checkpoints_below(path):
            trials.setdefault(os.path.dirname(checkpoint), []).append(checkpoint)
        if len(trials) > 1:
            return [_newest(trials[t]) for t in sorted(trials)]
    return [find_checkpoint(path)]


def every_checkpoint(path: str) -> list[str]:
    """Every checkpoint below `path` (a checkpoint itself: `[path]`), trial by trial, each
    trial's oldest first (by the number in `checkpoint_NNNNNN`). UsageError when there is none."""
    path = os.path.abspath(os.path.expanduser(path))
    if os.path.isfile(os.path.join(path, CHECKPOINT_MARKER)):
        return [path]
    find_checkpoint(path)  # the clear error for a missing folder or one without checkpoints
    found = _checkpoints_below(path)
    return sorted(found, key=lambda p: (os.path.dirname(p), _number(p), p))


def _number(checkpoint: str) -> int:
    digits = os.path.basename(checkpoint).removeprefix("checkpoint_")
    return int(digits) if digits.isdigit() else -1


def score(stats: dict[str, Any], by: str) -> float:
    """`stats`' value of `by` (a return statistic or an env episode metric); UsageError naming
    what is allowed when the evaluation has no such number."""
    metrics = stats.get("episode_metrics") or {}
    if by in RETURN_KEYS:
        return float(stats[by])
    if by in metrics:
        return float(metrics[by])
    raise UsageError(
        f"{by!r} is not a number this evaluation reports; allowed: "
        + ", ".join([*RETURN_KEYS, *sorted(metrics)]),
        key="--best-by",
    )


def best_per_trial(results: list[dict[str, Any]], by: str) -> list[dict[str, Any]]:
    """Per trial (a checkpoint's parent folder): its best checkpoint by `by` (the newest of
    equal ones) beside its newest."""
    trials: dict[str, list[dict[str, Any]]] = {}
    for stats in results:
        trials.setdefault(os.path.dirname(stats["checkpoint"]), []).append(stats)
    out = []
    for trial, runs in trials.items():
        best = max(reversed(runs), key=lambda r: score(r, by))
        out.append({
            "trial": trial, "by": by,
            "best": best["checkpoint"], "best_value": score(best, by),
            "newest": runs[-1]["checkpoint"], "newest_value": score(runs[-1], by),
        })  # fmt: skip
    return out


def _local_config(path: str, seed: int | None, evaluation_config: bool = False) -> dict[str, Any]:
    """The checkpoint's config dict, changed to sample locally with one env (and, with
    `evaluation_config`, with the settings of its `evaluation_config` but `explore`)."""
    try:
        with open(os.path.join(path, CTOR_FILE), "rb") as f:
            ctor = pickle.load(f)
        config = ctor["ctor_args_and_kwargs"][0][0]
    except Exception as e:
        from rllib_asor.rllib.modules import OLDER_CHECKPOINT, RETIRED_CLASSES

        if any(repr(name) in str(e) for name in RETIRED_CLASSES):
            raise UsageError(OLDER_CHECKPOINT, source=path) from None
        raise UsageError(
            f"cannot read the algorithm config ({type(e).__name__}: {e})",
            source=os.path.join(path, CTOR_FILE),
        ) from None
    config = config.to_dict() if hasattr(config, "to_dict") else dict(config)
    if evaluation_config:
        overrides = config.get("evaluation_config") or {}
        config.update({k: v for k, v in dict(overrides).items() if k != "explore"})
    config.update(
        num_env_runners=0,
        num_envs_per_env_runner=1,
        evaluation_num_env_runners=0,
        evaluation_interval=None,
        num_learners=0,
        create_env_on_driver=True,
    )
    if seed is not None:
        config["seed"] = seed
    return config


def _unreadable_file(path: str) -> tuple[str, str] | None:
    """(file, reason) for the first state file under `path` that does not unpickle."""
    for root, _, files in sorted(os.walk(path)):
        for name in sorted(files):
            if not name.endswith(".pkl"):
                continue
            full = os.path.join(root, name)
            try:
                with open(full, "rb") as f:
                    pickle.load(f)
            except Exception as e:
                return full, f"{type(e).__name__}: {' '.join(str(e).split())[:120]}"
    return None


def evaluate(
    path: str,
    episodes: int,
    explore: bool = False,
    seed: int | None = None,
    evaluation_config: bool = False,
) -> dict[str, Any]:
    """Restore the algorithm at `path` and run `episodes` episodes; return the statistics,
    with each episode's ``info["dynamics_id"]`` (None where the env reports none) and the
    returns per dynamics id."""
    from ray.rllib.algorithms.algorithm import Algorithm

    from rllib_asor.cli.cluster import start_ray
    from rllib_asor.evaluation.summary import summarize
    from rllib_asor.registry import env_names

    quiet.import_quietly("ray.rllib.algorithms.dreamerv3.utils.debugging")  # see its docstring
    config = _local_config(path, seed, evaluation_config)
    env_id = config.get("env")
    if isinstance(env_id, str):
        try:
            env_names.register_env(env_id)
        except ValueError as e:
            raise UsageError(one_line(e), source=path) from None
    bad = _unreadable_file(path)  # before Ray starts: one clean line naming the file
    if bad is not None:
        raise UsageError(f"cannot be read, the checkpoint is damaged ({bad[1]})", source=bad[0])
    start_ray(None, 1)
    algo = Algorithm.from_checkpoint(path, config=config)
    try:
        done = algo.env_runner.sample(num_episodes=episodes, explore=explore)
    finally:
        algo.stop()
    stats = summarize(done[:episodes])
    return {
        "checkpoint": path,
        "env": env_id if isinstance(env_id, str) else str(env_id),
        "episodes": len(stats["returns"]),
        "explore": explore,
        **{k: stats[k] for k in ("return_mean", "return_std", "return_min", "return_max")},
        "returns": stats["returns"],
        "lengths": stats["lengths"],
        "episode_metrics": stats["episode_metrics"],
        "seed": seed,
        "evaluation_config": evaluation_config,
        "dynamics_ids": stats["dynamics_ids"],
        "per_dynamics": stats["per_dynamics"],
    }


def run(args: argparse.Namespace) -> int:
    """`rllib evaluate`: print mean/std return and per-episode returns (or JSON); for a folder
    of several trials, the same for the newest checkpoint of each; with `--all-checkpoints`,
    for every checkpoint, then each trial's best by `--best-by` beside its newest."""
    if args.episodes < 1:
        raise UsageError(f"{args.episodes} is invalid: allowed an integer >= 1", key="--episodes")
    every, by = args.all_checkpoints, args.best_by
    if by != BEST_BY and not every:
        raise UsageError("is only read with --all-checkpoints", key="--best-by")
    paths = every_checkpoint(args.checkpoint) if every else trial_checkpoints(args.checkpoint)
    if len(paths) > 1 and not args.json:
        print(
            f"{len(paths)} checkpoints under {args.checkpoint}: evaluating every one"
            if every
            else f"{len(paths)} trials under {args.checkpoint}: evaluating the newest checkpoint of each"
        )
    results = []
    for path in paths:
        stats = evaluate(
            path, args.episodes, explore=args.explore, seed=args.seed,
            evaluation_config=args.evaluation_config,
        )  # fmt: skip
        if every:
            score(stats, by)  # a --best-by the env does not report fails now, not at the end
        results.append(stats)
        if not args.json:
            _print(stats)
    if every:
        best = best_per_trial(results, by)
        if args.json:
            print(json.dumps({"checkpoints": results, "best": best}))
        else:
            for b in best:
                print(
                    f"best by {by} in {b['trial']}: {os.path.basename(b['best'])} "
                    f"({b['best_value']:.3g}); the newest, {os.path.basename(b['newest'])}: "
                    f"{b['newest_value']:.3g}"
                )
    elif args.json:
        print(json.dumps(results if len(paths) > 1 else results[0]))
    sys.stdout.flush()
    return 0


def _print(stats: dict[str, Any]) -> None:
    policy = "stochastic (--explore)" if stats["explore"] else "deterministic"
    print(f"checkpoint: {stats['checkpoint']}")
    print(f"env: {stats['env']}  episodes: {stats['episodes']}  policy: {policy}")
    seed = stats["seed"]
    same = " (the default: the seed rllib ab evaluates with)" if seed == EVAL_SEED else ""
    print(f"seed: {seed}{same}")
    print(
        f"return: mean {stats['return_mean']:.3f}  std {stats['return_std']:.3f}  "
        f"min {stats['return_min']:.3f}  max {stats['return_max']:.3f}"
    )
    print("episode returns: " + " ".join(f"{r:g}" for r in stats["returns"]))
    print("episode lengths: " + " ".join(str(n) for n in stats["lengths"]))
    if stats["per_dynamics"]:
        print(
            "return per dynamics_id: "
            + "  ".join(
                f"{k}: {v['return_mean']:.3f} ({v['episodes']} ep)"
                for k, v in stats["per_dynamics"].items()
            )
        )
    if stats["episode_metrics"]:
        print(
            "env metrics (mean over episodes): "
            + "  ".join(f"{k} {v:.3g}" for k, v in stats["episode_metrics"].items())
        )
