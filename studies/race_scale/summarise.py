"""Summarise studies/race_scale: each file's success on unseen courses, and the rule's verdict
(README.md) on the paired difference scale − today, computed only once all 40 runs exist.

    .venv/bin/python studies/race_scale/summarise.py [STUDY_DIR]

Reads the run files of STUDY_DIR/runs/ (default: this folder) and writes table.md and summary.json there.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))

from studies.lib import paired_verdict  # noqa: E402

METRIC = "eval.per_map.*.success"
SEEDS = range(20)
MARGIN = -0.10
"""'as good' iff the 95 % BCa interval's lower end is above this (the rule)."""
WALL = "2-core machine, 2 runs at once"


def summarise(runs: Path) -> dict[str, Any]:
    return paired_verdict.summarise([runs.parent], METRIC, "today", ["scale"], SEEDS, MARGIN)


def table(res: dict[str, Any]) -> str:
    return paired_verdict.table(res, "today", WALL)


if __name__ == "__main__":
    paired_verdict.cli(HERE, summarise, table)
