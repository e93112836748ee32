"""Summarise studies/race_scale_rollout_2m: the many-runner setting with 32-step rollouts
(`rollout-2m`) against `ppo-asor.yaml` (race_scale_2m's `today-2m`) at the files' shared
2M-env-step stop, the rule's verdict once its 20 runs exist (README.md), and beside it the
declining runs and `rollout-2m` against race_scale_steps' `rollout` runs at 500k.

    .venv/bin/python studies/race_scale_rollout_2m/summarise.py [STUDY_DIR]

Reads the run files of STUDY_DIR/runs/, ../race_scale_2m/runs/ and ../race_scale_steps/runs/,
and writes table.md and summary.json in STUDY_DIR (default: this folder).
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

STUDY = PairedStudy(arms=("rollout-2m",), baseline="today-2m", also=("race_scale_2m",))


def summarise(runs: Path) -> dict[str, Any]:
    """The rule's summary, the declining seeds, and rollout-2m − rollout (500k)."""
    res = STUDY.summarise(runs)
    res["declining"] = {"rollout-2m": declining_seeds(runs, "rollout-2m")}
    res["rollout_2m_vs_500k"] = descriptive_pair(
        [runs.parent, runs.parent.parent / "race_scale_steps"],
        STUDY.metric,
        "rollout",
        "rollout-2m",
    )
    return res


def table(res: dict[str, Any]) -> str:
    """The rule's table, then the declining runs and rollout-2m against rollout at 500k."""
    p = res["rollout_2m_vs_500k"]
    rows = [STUDY.table(res), *declining_table(res["declining"]), ""]
    return "\n".join([*rows, descriptive_line(p, "rollout-2m − rollout (500k)")]) + "\n"


if __name__ == "__main__":
    folder = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent
    print(write_summary(folder, summarise, table))
