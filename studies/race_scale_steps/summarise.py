"""Summarise studies/race_scale_steps: each arm's success on unseen courses beside race_scale's
`today` runs, and the rule's verdict per arm (README.md), computed once its 20 runs exist.

    .venv/bin/python studies/race_scale_steps/summarise.py [STUDY_DIR]

Reads the run files of STUDY_DIR/runs/ and ../race_scale/runs/ (the baseline), and writes
table.md and summary.json in STUDY_DIR (default: this folder).
"""

from pathlib import Path

from studies.lib.paired_verdict import PairedStudy

STUDY = PairedStudy(arms=("rollout", "epochs"), also=("race_scale",))
summarise, table = STUDY.summarise, STUDY.table

if __name__ == "__main__":
    STUDY.cli(Path(__file__).resolve().parent)
