"""`rllib report RESULTS_DIR`: markdown tables and PNG learning curves from Tune results.

Reads every trial directory under RESULTS_DIR (a folder holding ``result.json``, one JSON object
per training iteration, and ``params.json``, the trial's algorithm config; symlinks followed),
groups trials by env, method (``PPO``, ``PPO+ASOR``, ``SAC+SRPO``, ...) and every other setting
that differs besides the seed, and writes ``report.md``,
``summary.json`` and one ``curves_<env>.png`` per env into the output folder. Files are written
atomically (temp file + ``os.replace``). Prints first the paired answer (`rllib compare`'s, when
the folder has a baseline and a treatment with seeds in common) or that the numbers are unpaired,
then one line per group whose ASOR looks inert, then the report's path.

Argument parsing only: reading, statistics and rendering are `rllib_asor.report`.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from rllib_asor.report.render import write_report
from rllib_asor.report.summary import DEFAULT_METRIC, DEFAULT_X


def _columns(value: str) -> list[str]:
    return [c.strip() for c in value.split(",") if c.strip()]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add `rllib report` arguments to `parser` (a subparser of the `rllib` command)."""
    parser.add_argument(
        "results_dir",
        metavar="RESULTS_DIR",
        help="folder with Tune results (searched recursively for result.json)",
    )
    parser.add_argument(
        "--out", metavar="DIR", default=None, help="output folder (default: RESULTS_DIR/report)"
    )
    parser.add_argument(
        "--metric",
        default=DEFAULT_METRIC,
        help=f"result key to compare, '/'-separated (default: {DEFAULT_METRIC})",
    )
    parser.add_argument(
        "--x", default=DEFAULT_X, help=f"x axis of the learning curves (default: {DEFAULT_X})"
    )
    parser.add_argument(
        "--last-n",
        type=int,
        default=1,
        metavar="N",
        help="final value = mean of each trial's last N iterations (default: 1)",
    )
    parser.add_argument(
        "--group-by",
        metavar="KEY",
        default=None,
        help="label groups by this dotted params key (e.g. asor.lambda_) instead of the "
        "method; trials whose other settings differ are still never lumped",
    )
    parser.add_argument(
        "--columns",
        metavar="KEY[,KEY]",
        type=_columns,
        action="extend",
        default=None,
        help="extra final-metric columns, or 'all' for every race/... and asor/... key "
        "(default: race/... and asor/{disc_acc,real_fraction,aug_reward_mean,lambda})",
    )


def run(args: argparse.Namespace) -> int:
    """Run `rllib report`; 0 on success, 2 (one line on stderr) on bad input."""
    try:
        report, md = write_report(
            args.results_dir,
            args.out,
            metric=args.metric,
            x=args.x,
            last_n=args.last_n,
            group_by=args.group_by,
            columns=args.columns,
        )
    except ValueError as e:
        print(f"rllib report: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"rllib report: error: {e}", file=sys.stderr)
        return 1
    for line in report.lead:
        print(line)
    for group in report.groups:
        if group.asor_health:
            print(group.asor_health)
    print(f"report: {md}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Stand-alone entry: ``python -m rllib_asor.cli.report RESULTS_DIR``."""
    parser = argparse.ArgumentParser(prog="rllib report", description=__doc__.splitlines()[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
