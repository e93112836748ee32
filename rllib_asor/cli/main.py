"""`rllib` command: argument parsing and dispatch to train / evaluate / report / compare / ab / data
/ schema."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from typing import NoReturn

from rllib_asor.cli import quiet
from rllib_asor.cli.errors import UsageError


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line on stderr (like every other bad input)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    """The full `rllib` parser."""
    from rllib_asor.cli import ab, compare, data, evaluate, quickstart, report, schema, train

    parser = _Parser(
        prog="rllib", description="Train and evaluate RLlib (new API stack) agents, with ASOR."
    )
    parser.add_argument("--version", action="version", version=_version())
    sub = parser.add_subparsers(
        dest="command", metavar="{train,evaluate,report,compare,ab,quickstart,data,schema}"
    )
    sub.required = True
    p_train = sub.add_parser(
        "train",
        help="train from a YAML file or --run/--env flags",
        usage="rllib train file PATH [options]\n       rllib train --run ALGO --env ID "
        "[--config JSON] [options]",
    )
    train.add_arguments(p_train)
    _add_verbose(p_train)
    p_train.set_defaults(func=train.run)
    p_eval = sub.add_parser("evaluate", help="run episodes with a trained checkpoint")
    evaluate.add_arguments(p_eval)
    _add_verbose(p_eval)
    p_eval.set_defaults(func=evaluate.run)
    p_quick = sub.add_parser(
        "quickstart",
        help="train a racer (~5 min), evaluate it on unseen courses, report + GIF (make train)",
    )
    quickstart.add_arguments(p_quick)
    _add_verbose(p_quick)
    p_quick.set_defaults(func=quickstart.run)
    p_report = sub.add_parser("report", help="tables and curves from a results directory")
    report.add_arguments(p_report)
    p_report.set_defaults(func=report.run)
    p_compare = sub.add_parser(
        "compare", help="each method against a baseline, paired by seed (docs/report.md)"
    )
    compare.add_arguments(p_compare)
    p_compare.set_defaults(func=compare.run)
    p_ab = sub.add_parser(
        "ab", help="does the file's asor: block help? paired seeds, evaluated (docs/report.md)"
    )
    ab.add_arguments(p_ab)
    _add_verbose(p_ab)
    p_ab.set_defaults(func=ab.run)
    p_data = sub.add_parser("data", help="offline datasets: collect, info, score (docs/offline.md)")
    data.add_arguments(p_data, common=_add_verbose)
    p_data.set_defaults(func=data.run)
    p_schema = sub.add_parser(
        "schema", help="the JSON Schema of the YAML experiment files (for an editor's YAML support)"
    )
    schema.add_arguments(p_schema)
    p_schema.set_defaults(func=schema.run)
    return parser


def _add_verbose(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--verbose",
        action="store_true",
        help=f"show every Ray/RLlib message (default: known-harmless ones are hidden; "
        f"also {quiet.VERBOSE_ENV}=1)",
    )


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        ours = version("rllib-asor")
    except PackageNotFoundError:  # running from a source tree that was not installed
        ours = "unknown"
    return f"rllib-asor {ours} (ray {version('ray')}, torch {version('torch')})"


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `rllib` console script; returns the exit status.

    0 success, 1 training failed (a trial errored), 2 bad input (one line per problem on
    stderr).
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # --help (0) or a usage error (2): return it, do not raise
        return e.code if isinstance(e.code, int) else 2
    if getattr(args, "verbose", False):
        os.environ[quiet.VERBOSE_ENV] = "1"
    if args.command not in ("report", "compare", "schema"):  # the commands that run Ray
        quiet.quiet_driver()
    try:
        return int(args.func(args) or 0)
    except UsageError as e:
        for line in str(e).splitlines():  # one line per problem
            print(f"rllib {args.command}: error: {line}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"rllib {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
