"""Summarise studies/race_scale_steps: each arm's success on unseen courses beside race_scale's
`today` runs, and the rule's verdict per arm (README.md), computed once its 20 runs exist.

    .venv/bin/python studies/race_scale_steps/summarise.py [STUDY_DIR]

Reads the run files of STUDY_DIR/runs/ and ../race_scale/runs/ (the baseline), and writes table.md
and summary.json in STUDY_DIR (default: this folder).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))

from studies.lib import paired_verdict  # noqa: E402

METRIC = "eval.per_map.*.success"
ARMS = ["rollout", "epochs"]
SEEDS = range(20)
MARGIN = -0.10
"""'as good' iff the 95 % BCa interval's lower end is above this (the rule)."""
WALL = "2-core machine, 2 runs at once"


def summarise(runs: Path) -> dict[str, Any]:
    folders = [runs.parent, runs.parent.parent / "race_scale"]
    return paired_verdict.summarise(folders, METRIC, "today", ARMS, SEEDS, MARGIN)


def table(res: dict[str, Any]) -> str:
    return paired_verdict.table(res, "today", WALL)


if __name__ == "__main__":
    paired_verdict.cli(HERE, summarise, table)
