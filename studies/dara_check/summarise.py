"""Summarise studies/dara_check: normalised scores per method and seed, and the verdicts of the
rule fixed in README.md (learns: mean ≥ 50; DARA against MAPLE, paired by seed).

    .venv/bin/python studies/dara_check/summarise.py [RUNS_DIR]

Reads RUNS_DIR/*.json (default: runs/ beside this file); `make results` writes table.md and
summary.json from it (studies/lib/pages.py, runner "script").
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
RULE_METHODS = ("maple", "maple_dara")
"""The methods the rule decides on; others (the exploratory `maple_dara_eta1`) are listed only."""
LEARNS_AT = 50.0
"""A method learns if its mean normalised score over the seeds is at least this (rule)."""
MARGIN = 10.0
"""DARA better (worse): mean Δ ≥ MARGIN (≤ −MARGIN) and Δ of that sign on every seed (rule)."""
LABELS = {
    "random": "random (reference)",
    "optimal": "best target policy (reference)",
    "maple": "MAPLE",
    "maple_dara": "MAPLE+DARA (η 0.1)",
    "maple_dara_eta1": "MAPLE+DARA, η 1 (exploratory, outside the rule)",
}


def normalised(score: float, random: float, optimal: float) -> float:
    """100·(R − R_random)/(R_optimal − R_random) on the same evaluation starts."""
    return 100 * (score - random) / (optimal - random)


def dara_verdict(deltas: list[float]) -> str:
    """The rule's verdict on DARA − MAPLE (normalised), paired by seed."""
    mean = float(np.mean(deltas))
    if mean >= MARGIN and all(d > 0 for d in deltas):
        return "DARA better"
    if mean <= -MARGIN and all(d < 0 for d in deltas):
        return "DARA worse"
    return "no clear difference at this budget"


def summarise(runs: Path) -> dict[str, Any]:
    """{method: {seed: {return, normalised}}, mean per method, the verdicts}."""
    raw: dict[str, dict[int, float]] = {}
    for path in sorted(Path(runs).glob("*.json")):
        run = json.loads(path.read_text())
        raw.setdefault(run["method"], {})[int(run["seed"])] = float(run["score"])
    methods: dict[str, Any] = {}
    for method, by_seed in raw.items():
        rows = {
            str(s): {
                "return": r,
                "normalised": normalised(r, raw["random"][s], raw["optimal"][s]),
            }
            for s, r in sorted(by_seed.items())
        }
        methods[method] = {
            "seeds": rows,
            "mean": float(np.mean([v["normalised"] for v in rows.values()])),
        }
    out: dict[str, Any] = {"methods": methods, "learns": {}, "dara_vs_maple": None}
    for m in RULE_METHODS:
        if m in methods:
            out["learns"][m] = methods[m]["mean"] >= LEARNS_AT
    if all(m in methods for m in RULE_METHODS):
        seeds = sorted(set(methods["maple"]["seeds"]) & set(methods["maple_dara"]["seeds"]))
        deltas = [
            methods["maple_dara"]["seeds"][s]["normalised"]
            - methods["maple"]["seeds"][s]["normalised"]
            for s in seeds
        ]
        out["dara_vs_maple"] = {
            "seeds": seeds,
            "deltas": deltas,
            "mean": float(np.mean(deltas)),
            "verdict": dara_verdict(deltas),
        }
    return out


def table(res: dict[str, Any]) -> str:
    """The markdown table (normalised score, return in brackets) and the rule's verdicts."""
    methods = res["methods"]
    seeds = sorted({s for m in methods.values() for s in m["seeds"]}, key=int)
    lines = [
        "| method | " + " | ".join(f"seed {s}" for s in seeds) + " | mean | learns (≥ 50) |",
        "|---" * (len(seeds) + 3) + "|",
    ]
    for key in [k for k in LABELS if k in methods] + sorted(set(methods) - set(LABELS)):
        m = methods[key]
        cells = [
            f"{m['seeds'][s]['normalised']:.1f} (R {m['seeds'][s]['return']:.2f})"
            if s in m["seeds"]
            else "—"
            for s in seeds
        ]
        learns = res["learns"].get(key)
        verdict = "—" if learns is None else ("yes" if learns else "no")
        lines.append(
            f"| {LABELS.get(key, key)} | " + " | ".join(cells) + f" | {m['mean']:.1f} | {verdict} |"
        )
    d = res["dara_vs_maple"]
    if d:
        per = ", ".join(f"seed {s}: {x:+.1f}" for s, x in zip(d["seeds"], d["deltas"], strict=True))
        lines += ["", f"DARA − MAPLE (normalised): mean {d['mean']:+.1f} ({per}): {d['verdict']}."]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    res = summarise(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE / "runs")
    print(table(res), end="")
