"""Summarise studies/race_scale: each file's success on unseen courses, and the rule's verdict
(README.md) on the paired difference scale − today, computed only once all 40 runs exist.

    .venv/bin/python studies/race_scale/summarise.py [STUDY_DIR]

Reads the run files of STUDY_DIR/runs/ (default: this folder) and writes table.md and
summary.json there.
"""

from pathlib import Path

from studies.lib.paired_verdict import PairedStudy

STUDY = PairedStudy(arms=("scale",))
summarise, table = STUDY.summarise, STUDY.table

if __name__ == "__main__":
    STUDY.cli(Path(__file__).resolve().parent)
