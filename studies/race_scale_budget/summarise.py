"""Summarise studies/race_scale_budget: the scale file at its 2M-env-step stop beside
race_scale's `today` runs (500k), and the rule's verdict (README.md), once its 20 runs exist.

    .venv/bin/python studies/race_scale_budget/summarise.py [STUDY_DIR]

Reads the run files of STUDY_DIR/runs/ and ../race_scale/runs/ (the baseline), and writes
table.md and summary.json in STUDY_DIR (default: this folder).
"""

from pathlib import Path

from studies.lib.paired_verdict import PairedStudy

STUDY = PairedStudy(arms=("scale-2m",), also=("race_scale",))
summarise, table = STUDY.summarise, STUDY.table

if __name__ == "__main__":
    STUDY.cli(Path(__file__).resolve().parent)
