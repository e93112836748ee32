"""Summarise the ESCP Walker2d study: per-method returns and the paired differences with
their 95% BCa intervals (scipy, via `rllib_asor.report.paired.paired_difference`), and the
verdict of the rule fixed in studies/escp_walker/README.md.

    .venv/bin/python studies/escp_walker/summarise.py [STUDY_DIR]

Reads the run files of STUDY_DIR/runs/ (default: this folder) and writes table.md and
summary.json there.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))
from studies.lib.run_files import read_runs  # noqa: E402  (after the path)

LEARNS_AT = 1000.0
"""ESCP 'learns' if its mean stationary return on unseen tasks is ≥ this (rule, docs)."""
SEEDS = 5
"""The rule's number of seeds (0-4): the validity bar is decided once ESCP has all of them."""
PRACTICAL = 0.05
"""A gain must also be ≥ 5 % of ESCP's mean return (rule, docs)."""
COMPARISONS = (
    ("escp", "escp_asor"),
    ("escp", "escp_asor_paper"),
    ("sac", "escp"),
)
SETTINGS = ("stationary", "ns")


def load(runs: Path) -> dict[str, dict[int, dict[str, float]]]:
    out: dict[str, dict[int, dict[str, float]]] = {}
    for run in read_runs(runs):
        out.setdefault(run["method"], {})[int(run["seed"])] = run["eval"]
    return out


def verdict(p: Any, base_mean: float) -> str:
    """The rule: gain iff the BCa interval is above 0 and the mean difference ≥ 5 % of the
    baseline's |mean|; harm iff the interval is below 0; else no detectable difference."""
    if p.pairs < 5 or not math.isfinite(p.ci_low):
        return "too few pairs"
    if p.ci_low > 0 and p.diff_mean >= PRACTICAL * abs(base_mean):
        return "gain"
    if p.ci_high < 0:
        return "harm"
    return "no detectable difference"


def summarise(runs: Path) -> dict[str, Any]:
    from rllib_asor.report.paired import paired_difference

    data = load(runs)
    methods = {
        m: {
            s: {
                "n": len(v),
                "mean": float(np.mean([x[s] for x in v.values()])),
                "std": float(np.std([x[s] for x in v.values()], ddof=1)) if len(v) > 1 else 0.0,
            }
            for s in SETTINGS
        }
        for m, v in data.items()
    }
    comps = []
    for base, treat in COMPARISONS:
        if base not in data or treat not in data:
            continue
        for s in SETTINGS:
            b = {k: v[s] for k, v in data[base].items()}
            t = {k: v[s] for k, v in data[treat].items()}
            try:
                p = paired_difference(b, t, baseline_name=base, treatment_name=treat, metric=s)
            except ValueError:
                continue
            row = p.to_json()
            row["rule"] = verdict(p, p.baseline_mean)
            comps.append(row)
    escp = methods.get("escp", {}).get("stationary", {"n": 0, "mean": float("nan")})
    learns = bool(escp["mean"] >= LEARNS_AT)
    if escp["n"] < SEEDS:
        answer = f"pending: the validity bar needs ESCP's {SEEDS} seeds ({escp['n']} so far)"
    elif not learns:
        answer = "budget too small: ESCP does not learn, the pairs do not test the claim"
    else:
        answer = "valid: read the escp_asor − escp rows by the rule"
    return {"methods": methods, "comparisons": comps, "escp_learns": learns, "answer": answer}


def table(res: dict[str, Any]) -> str:
    lines = [
        "| method | runs | unseen tasks, stationary | unseen tasks, non-stationary |",
        "|---|---|---|---|",
    ]
    for m, v in res["methods"].items():
        st, ns = v["stationary"], v["ns"]
        lines.append(
            f"| {m} | {st['n']} | {st['mean']:.0f} ± {st['std']:.0f} | "
            f"{ns['mean']:.0f} ± {ns['std']:.0f} |"
        )
    lines += [
        "",
        "| treatment − baseline | setting | pairs | mean diff | 95% BCa | p | rule |",
        "|---|---|---|---|---|---|---|",
    ]
    for c in res["comparisons"]:
        ci = "–" if c["ci_low"] is None else f"{c['ci_low']:.0f} … {c['ci_high']:.0f}"
        p = "–" if c["p_value"] is None else f"{c['p_value']:.2f}"
        lines.append(
            f"| {c['treatment']} − {c['baseline']} | {c['metric']} | {c['pairs']} | "
            f"{c['diff_mean']:+.0f} | {ci} | {p} | {c['rule']} |"
        )
    lines.append(f"\nESCP learns (stationary mean ≥ {LEARNS_AT:.0f}): {res['escp_learns']}")
    lines.append(f"The study's answer (the rule): {res['answer']}")
    return "\n".join(lines) + "\n"


def main() -> None:
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else HERE  # the study folder (default: here)
    res = summarise(out / "runs")
    (out / "summary.json").write_text(json.dumps(res, indent=1))
    (out / "table.md").write_text(table(res))
    print(table(res))


if __name__ == "__main__":
    main()
