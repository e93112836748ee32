"""`rllib compare RESULTS_DIR [...]`: each method against a baseline, paired by seed.

Finds the trials (symlinks followed), groups them so that a group's trials differ in the seed
only, pairs baseline and treatment trials by seed and prints per env (and per ``dynamics_id``
where evaluation recorded it): pairs, both means, the mean paired difference with its 95 % BCa
interval, a Wilcoxon signed-rank p-value, the probability of improvement and the IQM
(docs/report.md). Argument parsing only: the library is `rllib_asor.report.compare`.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `rllib compare`."""
    parser.add_argument(
        "results_dirs",
        nargs="+",
        metavar="RESULTS_DIR",
        help="folders with Tune results (searched recursively, symlinks followed)",
    )
    parser.add_argument(
        "--baseline",
        metavar="NAME",
        help="baseline group (a label or method as printed; default: the group without ASOR)",
    )
    parser.add_argument(
        "--metric",
        metavar="KEY",
        help="score trials by this result key (default: final evaluation, else evaluation "
        "during training, else training return)",
    )
    parser.add_argument(
        "--last-n",
        type=int,
        default=1,
        metavar="N",
        help="with a result key: mean of each trial's last N values (default 1)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON list on stdout")
    parser.add_argument(
        "--table",
        action="store_true",
        help="the paper's layout instead: tasks as rows, methods as columns, mean ± 95 %% "
        "interval over seeds, the best in bold (markdown)",
    )


def run(args: argparse.Namespace) -> int:
    """Run `rllib compare`; 0 on success, 2 (one line on stderr) on bad input."""
    from rllib_asor.report.compare import compare, render_text

    if args.last_n < 1:
        print(f"rllib compare: error: --last-n: {args.last_n} is invalid: allowed an integer >= 1",
              file=sys.stderr)  # fmt: skip
        return 2
    if getattr(args, "table", False):
        from rllib_asor.report.table import render_table, table_cells

        try:
            print(render_table(*table_cells(args.results_dirs, args.metric, args.last_n)), end="")
        except ValueError as e:
            print(f"rllib compare: error: {e}", file=sys.stderr)
            return 2
        return 0
    try:
        comp = compare(args.results_dirs, args.baseline, args.metric, args.last_n)
    except ValueError as e:
        print(f"rllib compare: error: {e}", file=sys.stderr)
        return 2
    if args.json:
        rows = []
        for r in comp.results:
            row = r.to_json()
            row["metric_description"] = comp.sources[r.env].description
            rows.append(row)
        print(json.dumps(rows, default=str))
    else:
        print(render_text(comp), end="")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Stand-alone entry: ``python -m rllib_asor.cli.compare RESULTS_DIR``."""
    parser = argparse.ArgumentParser(prog="rllib compare", description=__doc__.splitlines()[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
