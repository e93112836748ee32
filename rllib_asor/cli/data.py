"""`rllib data collect|info|score`: offline datasets (rllib_asor.data) from the command line.

- `collect`: train a policy per dynamics and write the random / medium / expert /
  medium-replay datasets of one env (docs/offline.md);
- `info`: validate a dataset and print its return statistics;
- `score`: D4RL-style normalised scores of a checkpoint under each dynamics of a dataset.

Argument parsing only; the work is in `rllib_asor.data`. Bad input is one line on stderr and
exit status 2 (a `UsageError`, like every other `rllib` command).
"""

from __future__ import annotations

import argparse
import json
import logging
from collections.abc import Callable

from rllib_asor.cli.errors import UsageError
from rllib_asor.data.collect import TRAINERS
from rllib_asor.data.format import DYNAMICS, QUALITIES


def add_arguments(
    parser: argparse.ArgumentParser,
    common: Callable[[argparse.ArgumentParser], None] | None = None,
) -> None:
    """Sub-commands and options of `rllib data` (a subparser of the `rllib` command);
    `common` adds the options every sub-command shares (`--verbose`)."""
    sub = parser.add_subparsers(dest="data_command", metavar="{collect,info,score}")
    sub.required = True
    c = sub.add_parser("collect", help="train a policy per dynamics and write the datasets")
    c.add_argument("--env", required=True, help="env id, e.g. rllib_asor/HopperShift-v0")
    c.add_argument("--out", default="data/offline", help="output root (default data/offline)")
    c.add_argument("--steps", type=int, required=True, help="env steps per (dynamics, quality)")
    c.add_argument("--dynamics", nargs="+", default=list(DYNAMICS), help="dynamics presets")
    c.add_argument("--qualities", nargs="+", default=list(QUALITIES), choices=QUALITIES)
    c.add_argument("--trainer", choices=TRAINERS, default="ppo", help="policy trainer (ppo)")
    c.add_argument(
        "--train-steps",
        "--sac-steps",
        dest="train_steps",
        type=int,
        default=200_000,
        help="trainer env steps per dynamics (0: untrained policy)",
    )
    c.add_argument("--seed", type=int, default=0)
    c.add_argument("--overwrite", action="store_true", help="replace an existing task dir")
    c.add_argument(
        "--torch-threads", type=int, default=1, help="torch intra-op threads (default 1)"
    )
    c.set_defaults(data_func=_collect)
    i = sub.add_parser("info", help="validate a dataset and print its return statistics")
    i.add_argument("path")
    i.set_defaults(data_func=_info)
    s = sub.add_parser("score", help="normalised scores of a checkpoint under each dynamics")
    s.add_argument("checkpoint")
    s.add_argument("--data", required=True, help="the task dir, e.g. data/offline/hopper")
    s.add_argument("--episodes", type=int, default=5)
    s.set_defaults(data_func=_score)
    for p in (c, i, s):
        if common is not None:
            common(p)


def run(args: argparse.Namespace) -> int:
    """Run `rllib data ...`; 0 on success, UsageError (exit 2) on bad input."""
    logging.getLogger("ray.data").setLevel(logging.WARNING)  # one progress log per write
    try:
        args.data_func(args)
    except ValueError as err:
        raise UsageError(str(err)) from None
    return 0


def _collect(args: argparse.Namespace) -> None:
    import torch

    from rllib_asor.data.collect import collect

    # Measured on 2 shared cores: OpenMP threads spinning under load made SAC ~10x slower.
    torch.set_num_threads(args.torch_threads)
    collect(
        args.env, args.out, args.steps, dynamics=args.dynamics, qualities=args.qualities,
        train_steps=args.train_steps, trainer=args.trainer, seed=args.seed,
        overwrite=args.overwrite,
    )  # fmt: skip


def _info(args: argparse.Namespace) -> None:
    from rllib_asor.data.format import load_dataset

    ds = load_dataset(args.path)
    info = {
        "env": ds.env,
        "datasets": ds.manifest["datasets"],
        "reference_returns": ds.manifest["reference_returns"],
    }
    print(json.dumps(info, indent=2))


def _score(args: argparse.Namespace) -> None:
    from rllib_asor.data.scoring import evaluate

    print(json.dumps(evaluate(args.checkpoint, args.data, episodes=args.episodes), indent=2))
