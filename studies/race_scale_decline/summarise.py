"""Summarise studies/race_scale_decline: does each rerun reproduce its seed's stored training
curve (studies/race_scale_budget), and its learning statistics per 125,000 env steps.

    .venv/bin/python studies/race_scale_decline/summarise.py [STUDY_DIR]

Writes table.md and summary.json in STUDY_DIR (default: this folder).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

from studies.lib.common import window_means, write_summary
from studies.lib.run_files import existing, read_run, read_runs, run_file

STORED = Path(__file__).resolve().parents[1] / "race_scale_budget" / "runs"
EVERY = 125_000
POLICY, ASOR = "learners/default_policy/", "learners/asor_disc.default_policy/"
READING = {
    "success": "race/success_rate",
    "entropy": POLICY + "entropy",
    "KL": POLICY + "mean_kl_loss",
    "lr": POLICY + "default_optimizer_learning_rate",
    "value EV": POLICY + "vf_explained_var",
    "λ": ASOR + "lambda",
    "bonus share": ASOR + "bonus_share",
    "D acc real": ASOR + "disc_acc_real",
    "D acc gen": ASOR + "disc_acc_fake",
    # added after the first look (README.md): what the races did
    "trapped": "race/trapped_rate",
    "needless jumps": "race/unnecessary_jump_rate",
}
"""Column → the trace's key (README.md, "Reading")."""


def _same(a: float, b: float | None) -> bool:
    """Equal training success, NaN (no race ended in the iteration) matching NaN."""
    return a == b or (b is not None and math.isnan(a) and math.isnan(b))


def reproduced(run: dict[str, Any]) -> dict[str, Any] | None:
    """How the rerun's training success matches the stored `scale-2m` run of its seed, over the
    rerun's iterations (a switched method: the same up to its switch); None: no stored run."""
    path = existing(run_file(STORED, f"scale-2m-{run['seed']}"))
    if path is None:
        return None
    stored = {int(step): success for step, success, _ in read_run(path)["curve"]}
    same = [_same(s, stored.get(int(step))) for step, s, _ in run["curve"]]
    first = same.index(False) if False in same else None
    return {"iterations": len(same), "identical": sum(same), "first_difference": first}


def summarise(runs: Path) -> dict[str, Any]:
    """Per run: the reproduction check and the reading per EVERY env steps."""
    out: dict[str, Any] = {}
    for run in read_runs(runs):
        steps = [int(step) for step, _, _ in run["curve"]]
        columns = {
            c: window_means(steps, [t.get(k) for t in run["trace"]], EVERY, max(steps))
            for c, k in READING.items()
        }
        ends = range(EVERY, max(steps) + 1, EVERY)
        rows = [
            {"steps": end, **{c: means[i] for c, means in columns.items()}}
            for i, end in enumerate(ends)
        ]
        out[f"{run['method']}-{run['seed']}"] = {
            "eval_success": run["eval"]["mean"]["success"],
            "reproduced": reproduced(run),
            "reading": rows,
        }
    return out


def _cell(value: float | None) -> str:
    return "–" if value is None else f"{value:.3g}"


def table(res: dict[str, Any]) -> str:
    """One table per run: its reading per EVERY env steps, under its reproduction check."""
    parts = []
    for name, run in res.items():
        rep = run["reproduced"]
        check = (
            "no stored run of this seed"
            if rep is None
            else f"{rep['identical']} of {rep['iterations']} iterations' training success "
            f"identical to race_scale_budget's scale-2m run (first difference: "
            f"{'none' if rep['first_difference'] is None else 'iteration ' + str(rep['first_difference'])})"
        )
        head = "| env steps | " + " | ".join(READING) + " |"
        rule = "|---" * (len(READING) + 1) + "|"
        body = [
            f"| {r['steps']:,} | " + " | ".join(_cell(r[c]) for c in READING) + " |"
            for r in run["reading"]
        ]
        parts.append(
            f"**{name}** (success on unseen courses after training: "
            f"{run['eval_success']:.3f}; {check})\n\n" + "\n".join([head, rule, *body])
        )
    return "\n\n".join(parts) + "\n"


if __name__ == "__main__":
    folder = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent
    print(write_summary(folder, summarise, table))
