"""Summarise studies/race_scale_2m: the scale file (race_scale_budget's `scale-2m`) against
`ppo-asor.yaml` (`today-2m`) at their shared 2M-env-step stop, the rule's verdict once its 20
runs exist (README.md), and beside it the declining runs of each and `today-2m` against
race_scale's `today` runs at 500k.

    .venv/bin/python studies/race_scale_2m/summarise.py [STUDY_DIR]

Reads the run files of STUDY_DIR/runs/, ../race_scale_budget/runs/ and ../race_scale/runs/, and
writes table.md and summary.json in STUDY_DIR (default: this folder).
"""

from pathlib import Path

from studies.lib.paired_verdict import PairedStudy

STUDY = PairedStudy(
    arms=("scale-2m",),
    baseline="today-2m",
    also=("race_scale_budget",),
    declining=(("", "today-2m"), ("race_scale_budget", "scale-2m")),
    beside=("race_scale", "today", "today-2m"),
)
summarise, table = STUDY.summarise, STUDY.table

if __name__ == "__main__":
    STUDY.cli(Path(__file__).resolve().parent)
