"""Summarise studies/race_scale: each file's success on unseen courses, and the rule's verdict
(README.md) on the paired difference scale − today, computed only once all 40 runs exist.

    .venv/bin/python studies/race_scale/summarise.py [STUDY_DIR]

Reads STUDY_DIR/runs/*.json (default: this folder) and writes table.md and summary.json there.
"""

from __future__ import annotations

import json
import statistics
import sys
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))

METRIC = "eval.per_map.*.success"
SEEDS = range(20)
MARGIN = -0.10
"""'as good' iff the 95 % BCa interval's lower end is above this (the rule)."""


def verdict(low: float, high: float) -> str:
    if low > MARGIN:
        return "as good"
    if high < 0:
        return "worse"
    return "not decided at 20 pairs"


def summarise(runs: Path) -> dict[str, Any]:
    from rllib_asor.report.paired import paired_difference
    from studies.lib.compare import load_metric_by_seed

    by_seed = load_metric_by_seed([runs.parent], METRIC)
    walls: dict[str, list[float]] = {}
    for path in sorted(runs.glob("*.json")):
        run = json.loads(path.read_text())
        walls.setdefault(run["method"], []).append(run["train_wall_s"])
    methods = {
        m: {
            "runs": len(v),
            "mean": statistics.fmean(v.values()),
            "std": statistics.stdev(v.values()) if len(v) > 1 else 0.0,
            "dead": sum(x == 0 for x in v.values()),
            "train_wall_s": statistics.fmean(walls.get(m, [float("nan")])),
        }
        for m, v in sorted(by_seed.items())
    }
    today, scale = by_seed.get("today", {}), by_seed.get("scale", {})
    complete = set(today) >= set(SEEDS) and set(scale) >= set(SEEDS)
    out: dict[str, Any] = {"methods": methods, "complete": complete}
    if complete:
        p = paired_difference(today, scale, baseline_name="today", treatment_name="scale",
                              metric=METRIC)  # fmt: skip
        out["paired"] = p.to_json()
        out["verdict"] = verdict(p.ci_low, p.ci_high)
    else:
        done = sum(len(v) for v in (today, scale))
        out["verdict"] = (
            f"not yet: {done} of {2 * len(SEEDS)} runs (the rule decides once all exist)"
        )
    return out


def table(res: dict[str, Any]) -> str:
    lines = [
        "| file | runs | success on unseen courses (mean ± sd) | seeds at 0 | training wall s (2-core machine, 2 runs at once) |",
        "|---|---|---|---|---|",
    ]  # fmt: skip
    for m, v in res["methods"].items():
        lines.append(
            f"| {m} | {v['runs']} | {v['mean']:.3f} ± {v['std']:.3f} | {v['dead']} | "
            f"{v['train_wall_s']:.0f} |"
        )
    if "paired" in res:
        p = res["paired"]
        lines += [
            "",
            "| scale − today | pairs | mean diff | 95 % BCa | Wilcoxon p (two-sided) |",
            "|---|---|---|---|---|",
            f"| success | {p['pairs']} | {p['diff_mean']:+.3f} | {p['ci_low']:+.3f} … "
            f"{p['ci_high']:+.3f} | {p['p_value']:.2f} |",
        ]
    lines.append(f"\nVerdict (README.md's rule): **{res['verdict']}**")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    folder = Path(sys.argv[1]) if len(sys.argv) > 1 else HERE
    res = summarise(folder / "runs")
    (folder / "summary.json").write_text(json.dumps(res, indent=1))
    (folder / "table.md").write_text(table(res))
    print(table(res))
