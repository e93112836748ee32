"""Summarise studies/race_scale_2m: the scale file (race_scale_budget's `scale-2m`) against
`ppo-asor.yaml` (`today-2m`) at their shared 2M-env-step stop, the rule's verdict once its 20
runs exist (README.md), and beside it the declining runs of each and `today-2m` against
race_scale's `today` runs at 500k.

    .venv/bin/python studies/race_scale_2m/summarise.py [STUDY_DIR]

Reads the run files of STUDY_DIR/runs/, ../race_scale_budget/runs/ and ../race_scale/runs/, and
writes table.md and summary.json in STUDY_DIR (default: this folder).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from studies.lib.common import write_summary
from studies.lib.paired_verdict import (
    PairedStudy,
    declining_seeds,
    declining_table,
    descriptive_line,
    descriptive_pair,
)

STUDY = PairedStudy(arms=("scale-2m",), baseline="today-2m", also=("race_scale_budget",))


def summarise(runs: Path) -> dict[str, Any]:
    """The rule's summary, per method the declining seeds, and today-2m − today (500k)."""
    res = STUDY.summarise(runs)
    studies = runs.parent.parent
    res["declining"] = {
        "today-2m": declining_seeds(runs, "today-2m"),
        "scale-2m": declining_seeds(studies / "race_scale_budget" / "runs", "scale-2m"),
    }
    res["today_2m_vs_500k"] = descriptive_pair(
        [runs.parent, studies / "race_scale"], STUDY.metric, "today", "today-2m"
    )
    return res


def table(res: dict[str, Any]) -> str:
    """The rule's table, then the declining runs and today-2m against today at 500k."""
    return (
        "\n".join(
            [
                STUDY.table(res),
                *declining_table(res["declining"]),
                "",
                descriptive_line(res["today_2m_vs_500k"], "today-2m − today (500k)"),
            ]
        )
        + "\n"
    )


if __name__ == "__main__":
    folder = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent
    print(write_summary(folder, summarise, table))
