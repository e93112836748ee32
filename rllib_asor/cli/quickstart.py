"""`rllib quickstart` (what `make train` runs): train a racer, then show what it learned.

1. trains `tuned_examples/race/ppo-asor-quickstart.yaml` (PPO + ASOR on the obstacle race,
   250k env steps, about 5 minutes on 2 idle cores) with the live progress line of `rllib train`;
2. evaluates the trained policy on every map, on course seeds training never drew;
3. writes into the experiment's `report/`: report.md and learning curves (`rllib report`),
   race_eval.md / race_eval.json (the evaluation) and racer.gif (one episode);
4. ends with a short summary: what was trained, the success rate, where the files are, and
   the command and expected time of the full run.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path
from typing import Any

from rllib_asor.cli import experiment, train
from rllib_asor.cli.errors import UsageError
from rllib_asor.registry.families import RACE, family_of

DEFAULT_FILE = "tuned_examples/race/ppo-asor-quickstart.yaml"
FULL_RUN = "tuned_examples/race/ppo-asor-curriculum.yaml"
FULL_RUN_STEPS = 2_000_000
GIF_MAP = 2
"""Map of the GIF ("stairs"): one of the two shortest courses, the curriculum's first stage."""
TEST_EPISODE_STEPS = 100
REPORT_LAST_N = 10
"""Training metrics in the report: mean of the last 10 iterations (one is a handful of episodes)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `rllib quickstart`."""
    parser.add_argument(
        "--file", default=DEFAULT_FILE, help=f"race experiment to train (default {DEFAULT_FILE})"
    )
    parser.add_argument(
        "--episodes", type=int, default=3, help="evaluation courses per map (default 3)"
    )
    parser.add_argument("--storage-path", help=f"results root (default {train.DEFAULT_STORAGE})")
    parser.add_argument(
        "--test", action="store_true", help="smoke run: the --test budget and 100-step episodes"
    )
    parser.add_argument(
        "--fresh",
        action="store_true",
        help="train again: an earlier run's folder is renamed NAME.replaced-TIME (a rerun "
        "otherwise keeps the finished run and evaluates it again)",
    )


def run(args: argparse.Namespace) -> int:
    """Train, evaluate, report, GIF, summary; 0 on success, 1 if training failed."""
    if args.episodes < 1:
        raise UsageError(f"{args.episodes} is invalid: allowed an integer >= 1", key="--episodes")
    path = _find_file(args.file)
    _check_one_race_trial(path)  # before training, not after
    print(
        f"rllib quickstart: training {path} "
        + ("(smoke run)" if args.test else "(about 5 min on 2 idle cores; Ctrl-C stops it)"),
        flush=True,
    )
    t0 = time.monotonic()
    train_args = argparse.Namespace(
        source=[],
        config_file=path,
        run=None,
        env=None,
        config=None,
        name=None,
        test=args.test,
        num_env_runners=None,
        stop=None,
        storage_path=args.storage_path,
        resume=False,
        fresh=args.fresh,
        address=None,
        checkpoint_freq=None,
        keep_checkpoints=None,
    )
    [(exp, results)] = train.train(train_args)
    train_s = time.monotonic() - t0
    if train.print_summary(exp, results):
        return 1
    result = results[0]
    out = Path(train.storage_path(train_args, exp), exp.name, "report")
    max_steps = TEST_EPISODE_STEPS if args.test else _episode_steps(exp)
    print(f"rllib quickstart: evaluating on {args.episodes} unseen courses per map ...", flush=True)
    files, evaluation = _evaluate_and_record(result.checkpoint.path, out, args.episodes, max_steps)
    from rllib_asor.report.render import make_report

    report = make_report(Path(out).parent, out, last_n=REPORT_LAST_N)
    with report.open("a", encoding="utf-8") as f:  # the number that matters, in the report too
        f.write(_evaluation_section(evaluation, max_steps))
    files["report"] = report
    files["curves"] = next(out.glob("curves_*.png"), None)
    _print_final(exp, result, evaluation, files, train_s, args.test)
    return 0


def _find_file(path: str) -> str:
    if os.path.isfile(path):
        return path
    bundled = Path(__file__).resolve().parents[2] / path  # a source checkout's examples
    if bundled.is_file():
        return str(bundled)
    raise UsageError("not found; allowed: a race experiment YAML file", source=path)


def _check_one_race_trial(path: str) -> None:
    exps = experiment.load_file(path)
    if len(exps) != 1 or exps[0].num_trials != 1:
        raise UsageError("allowed: a file with one experiment of one trial", source=path)
    if family_of(exps[0].env) is not RACE:
        allowed = ", ".join(p + "..." for p in RACE.prefixes)
        raise UsageError(f"{exps[0].env!r} is not the race: allowed envs {allowed}", source=path)


def _episode_steps(exp: Any) -> int:
    return int((exp.config.get("env_config") or {}).get("max_episode_steps", 1000))


def _evaluate_and_record(
    checkpoint: str, out: Path, episodes: int, max_steps: int
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The race evaluation (stochastic policy, as the studies) and a GIF; their files."""
    from rllib_asor.evaluation.rollout import module_policy, policy_module
    from rllib_asor.race.evaluation import evaluate, record_gif

    policy = module_policy(policy_module(checkpoint), explore=True)
    evaluation = evaluate(policy, episodes, max_steps)
    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, Any] = {"checkpoint": checkpoint}
    files["evaluation"] = _write(out / "race_eval.json", json.dumps(evaluation, indent=1) + "\n")
    _write(out / "race_eval.md", _evaluation_table(evaluation))
    gif = out / "racer.gif"
    episode = record_gif(policy, gif, GIF_MAP, max_steps=max_steps)
    files["gif"] = (
        f"{gif} (map {GIF_MAP}, {'finished' if episode.get('success') else 'not finished'})"
    )
    return files, evaluation


def _evaluation_table(evaluation: dict[str, Any]) -> str:
    from rllib_asor.race.evaluation import COLUMNS

    rows = ["| map | " + " | ".join(t for _, t in COLUMNS) + " |", "|---|" + "---|" * len(COLUMNS)]
    for m, values in [*evaluation["per_map"].items(), ("mean", evaluation["mean"])]:
        rows.append(f"| {m} | " + " | ".join(f"{values[k]:.3f}" for k, _ in COLUMNS) + " |")
    return "\n".join(rows) + "\n"


def _evaluation_section(evaluation: dict[str, Any], max_steps: int) -> str:
    n = len(evaluation["episodes"])
    return (
        f"\n## Evaluation on unseen courses\n\n{n} episodes ({n // len(evaluation['per_map'])} "
        f"per map, course seeds never drawn in training, stochastic policy, at most {max_steps} "
        f"steps), `rllib_asor.race.evaluation`:\n\n{_evaluation_table(evaluation)}"
    )


def _write(path: Path, text: str) -> Path:
    from rllib_asor.report.render import atomic_write

    atomic_write(path, text.encode())
    return path


def _print_final(
    exp: Any,
    result: Any,
    evaluation: dict[str, Any],
    files: dict[str, Any],
    train_s: float,
    test: bool,
) -> None:
    m = result.metrics or {}
    steps = int(m.get("num_env_steps_sampled_lifetime") or 0)
    per_map = " ".join(f"{v['success']:.2f}" for v in evaluation["per_map"].values())
    n = len(evaluation["episodes"])
    print()
    method = exp.run + (" + ASOR" if exp.asor is not None else "")
    print(
        f"Trained {method} on the obstacle race ({exp.env}): {steps:,} env steps "
        f"in {train_s / 60:.1f} min."
    )
    print(
        f"Evaluated on {n} unseen courses ({n // len(evaluation['per_map'])} per map, "
        f"stochastic policy): success per map 0-9: {per_map}"
    )
    for name, path in files.items():
        if path is not None:
            print(f"  {name:<10} {path}")
    if steps and not test:
        hours = FULL_RUN_STEPS / (steps / train_s) / 3600
        print(
            f"The full run ({FULL_RUN_STEPS / 1e6:g}M env steps, ~{hours:.1f} h here): "
            f"rllib train file {FULL_RUN}"
        )
    print(
        f"rllib quickstart: success rate {evaluation['mean']['success']:.2f} on unseen courses"
        + (" (smoke run: --test budget)" if test else "")
    )
