"""Summarise studies/race_scale_rollout_2m: the many-runner setting with 32-step rollouts
(`rollout-2m`) against `ppo-asor.yaml` (race_scale_2m's `today-2m`) at the files' shared
2M-env-step stop, the rule's verdict once its 20 runs exist (README.md), and beside it the
declining runs and `rollout-2m` against race_scale_steps' `rollout` runs at 500k.

    .venv/bin/python studies/race_scale_rollout_2m/summarise.py [STUDY_DIR]

Reads the run files of STUDY_DIR/runs/, ../race_scale_2m/runs/ and ../race_scale_steps/runs/,
and writes table.md and summary.json in STUDY_DIR (default: this folder).
"""

from pathlib import Path

from studies.lib.paired_verdict import PairedStudy

STUDY = PairedStudy(
    arms=("rollout-2m",),
    baseline="today-2m",
    also=("race_scale_2m",),
    declining=(("", "rollout-2m"),),
    beside=("race_scale_steps", "rollout", "rollout-2m"),
)
summarise, table = STUDY.summarise, STUDY.table

if __name__ == "__main__":
    STUDY.cli(Path(__file__).resolve().parent)
