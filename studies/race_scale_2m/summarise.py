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

from rllib_asor.report.paired import paired_difference
from studies.lib.common import window_means, write_summary
from studies.lib.compare import load_metric_by_seed
from studies.lib.paired_verdict import PairedStudy
from studies.lib.run_files import read_runs

STUDY = PairedStudy(arms=("scale-2m",), baseline="today-2m", also=("race_scale_budget",))
WINDOW, STOP = 125_000, 2_000_000
PEAK, LOW = 0.6, 0.4
"""A run declines iff its training success reaches PEAK in some WINDOW and is below LOW over the
last one (README.md)."""


def windows(curve: list[list[float]]) -> list[float | None]:
    """Mean training success (`race/success_rate`, NaN iterations left out) per WINDOW env
    steps up to STOP; None for a window without a finished race."""
    return window_means([c[0] for c in curve], [c[1] for c in curve], WINDOW, STOP)


def declines(curve: list[list[float]]) -> bool:
    """README.md's reading: peak ≥ PEAK in some window, below LOW over the last window."""
    w = windows(curve)
    return max((x for x in w if x is not None), default=0.0) >= PEAK and (w[-1] or 0.0) < LOW


def summarise(runs: Path) -> dict[str, Any]:
    """The rule's summary, per method the declining seeds, and today-2m − today (500k)."""
    res = STUDY.summarise(runs)
    studies = runs.parent.parent
    res["declining"] = {}
    for folder, method in (
        (runs, "today-2m"),
        (studies / "race_scale_budget" / "runs", "scale-2m"),
    ):
        done = [r for r in read_runs(folder) if r["method"] == method]
        res["declining"][method] = {
            "runs": len(done),
            "seeds": sorted(r["seed"] for r in done if declines(r["curve"])),
        }
    by_seed = load_metric_by_seed([runs.parent, studies / "race_scale"], STUDY.metric)
    now, then = by_seed.get("today-2m", {}), by_seed.get("today", {})
    seeds = sorted(set(now) & set(then))
    res["today_2m_vs_500k"] = (
        paired_difference(
            {s: then[s] for s in seeds},
            {s: now[s] for s in seeds},
            baseline_name="today",
            treatment_name="today-2m",
            metric=STUDY.metric,
        ).to_json()
        if len(seeds) >= 3  # fewer pairs give no BCa interval
        else {"pairs": len(seeds)}
    )
    return res


def table(res: dict[str, Any]) -> str:
    """The rule's table, then the declining runs and today-2m against today at 500k."""
    lines = [
        STUDY.table(res),
        "| method | runs | declining (README.md's reading) | seeds |",
        "|---|---|---|---|",
    ]
    for method, d in res["declining"].items():
        lines.append(
            f"| {method} | {d['runs']} | {len(d['seeds'])} | {', '.join(map(str, d['seeds'])) or '–'} |"
        )
    p = res["today_2m_vs_500k"]
    lines.append("")
    if "diff_mean" in p:
        lines.append(
            f"today-2m − today (500k), descriptive: {p['pairs']} pairs, {p['diff_mean']:+.3f}, "
            f"95 % BCa {p['ci_low']:+.3f} … {p['ci_high']:+.3f}"
        )
    else:
        lines.append(f"today-2m − today (500k): {p['pairs']} pairs so far")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    folder = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent
    print(write_summary(folder, summarise, table))
