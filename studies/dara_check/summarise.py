"""Summarise studies/dara_check: normalised scores per method and seed, and the verdicts of the
three rules fixed in README.md (the first on seeds 0–2, the confirmatory one on seeds 3–5, the
coverage rule on seeds 6–8 and the data whose target part covers the source's states).

    .venv/bin/python studies/dara_check/summarise.py [RUNS_DIR]

Reads the run files of RUNS_DIR (default: runs/ beside this file); `make results` writes
table.md and summary.json from it (studies/lib/pages.py, runner "script").
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from studies.lib.compare import sign_rule
from studies.lib.run_files import read_runs

HERE = Path(__file__).resolve().parent
MARGIN = 10.0
"""DARA better (worse): mean Δ ≥ MARGIN (≤ −MARGIN) and Δ of that sign on every seed (every rule)."""
LABELS = {
    "random": "random (reference)",
    "still": "never moves, a = 0 (reference)",
    "optimal": "best target policy (reference)",
    "maple": "MAPLE",
    "maple_dara": "MAPLE+DARA (η 0.1, σ 1: shipped)",
    "maple_dara_eta1": "MAPLE+DARA, η 1 (exploratory)",
    "maple_dara_eta3": "MAPLE+DARA, η 3 (exploratory)",
    "maple_dara_noise01": "MAPLE+DARA, σ 0.1 (exploratory)",
    "maple_dara_eta1_noise01": "MAPLE+DARA, η 1, σ 0.1",
    "maple+cover": "MAPLE, covering data",
    "maple_dara+cover": "MAPLE+DARA (η 0.1, σ 1: shipped), covering data",
    "maple_dara_eta1_noise01+cover": "MAPLE+DARA, η 1, σ 0.1, covering data",
}


class Rule(NamedTuple):
    """One decision rule of README.md: its seeds, its DARA and MAPLE arms, its bar for *learns*."""

    name: str
    seeds: tuple[int, ...]
    dara: str
    learns_at: float
    above_still: bool
    """Also above the never-moving policy on every seed (the later rules)."""
    maple: str = "maple"

    def learns(self, by_seed: dict[str, float], still: dict[str, float]) -> bool:
        scores = [by_seed[str(s)] for s in self.seeds]
        if self.above_still and not all(by_seed[str(s)] > still[str(s)] for s in self.seeds):
            return False
        return float(np.mean(scores)) >= self.learns_at

    @property
    def bar(self) -> str:
        return f"mean ≥ {self.learns_at:g}" + (
            ", > never moving per seed" if self.above_still else ""
        )


RULES = (
    Rule("first rule", (0, 1, 2), "maple_dara", 50.0, above_still=False),
    Rule("confirmatory rule", (3, 4, 5), "maple_dara_eta1_noise01", 70.0, above_still=True),
    Rule("coverage rule", (6, 7, 8), "maple_dara_eta1_noise01+cover", 70.0, True, "maple+cover"),
)


def normalised(score: float, random: float, optimal: float) -> float:
    """100·(R − R_random)/(R_optimal − R_random) on the same evaluation starts."""
    return 100 * (score - random) / (optimal - random)


def dara_verdict(deltas: list[float]) -> str:
    """A rule's verdict on DARA − MAPLE (normalised), paired by seed."""
    return {1: "DARA better", -1: "DARA worse", 0: "no clear difference at this budget"}[
        sign_rule(deltas, MARGIN)
    ]


def _norm(raw: dict[str, dict[int, float]]) -> dict[str, dict[str, dict[str, float]]]:
    """{method: {seed: {return, normalised}}} for the seeds whose references were run."""
    out: dict[str, dict[str, dict[str, float]]] = {}
    for method, by_seed in raw.items():
        out[method] = {
            str(s): {"return": r, "normalised": normalised(r, raw["random"][s], raw["optimal"][s])}
            for s, r in sorted(by_seed.items())
            if s in raw.get("random", {}) and s in raw.get("optimal", {})
        }
    return out


def summarise(runs: Path) -> dict[str, Any]:
    """Per rule: each method's normalised scores on the rule's seeds, their mean, *learns* for
    MAPLE and the rule's DARA arm, and DARA − MAPLE paired by seed (when every run exists)."""
    raw: dict[str, dict[int, float]] = {}
    for run in read_runs(Path(runs)):
        raw.setdefault(run["method"], {})[int(run["seed"])] = float(run["score"])
    scores = _norm(raw)
    out: dict[str, Any] = {}
    for rule in RULES:
        seeds = [str(s) for s in rule.seeds]
        methods = {
            m: {
                "seeds": {s: by[s] for s in seeds if s in by},
                "mean": float(np.mean([by[s]["normalised"] for s in seeds if s in by])),
            }
            for m, by in scores.items()
            if any(s in by for s in seeds)
        }
        part: dict[str, Any] = {"seeds": seeds, "bar": rule.bar, "methods": methods, "learns": {}}
        complete = {m for m, v in methods.items() if len(v["seeds"]) == len(seeds)}
        if "still" in complete or not rule.above_still:
            still = {
                s: v["normalised"] for s, v in methods.get("still", {"seeds": {}})["seeds"].items()
            }
            for m in (rule.maple, rule.dara):
                if m in complete:
                    by = {s: v["normalised"] for s, v in methods[m]["seeds"].items()}
                    part["learns"][m] = rule.learns(by, still)
        part["dara_vs_maple"] = None
        if {rule.maple, rule.dara} <= complete:
            deltas = [
                methods[rule.dara]["seeds"][s]["normalised"]
                - methods[rule.maple]["seeds"][s]["normalised"]
                for s in seeds
            ]
            part["dara_vs_maple"] = {
                "dara": rule.dara,
                "maple": rule.maple,
                "deltas": deltas,
                "mean": float(np.mean(deltas)),
                "verdict": dara_verdict(deltas),
            }
        out[rule.name] = part
    return out


def table(res: dict[str, Any]) -> str:
    """One markdown table per rule (normalised score, return in brackets) and its verdicts."""
    lines: list[str] = []
    for name, part in res.items():
        methods, seeds = part["methods"], part["seeds"]
        if not methods:
            continue
        lines += [
            f"**{name}** (seeds {', '.join(seeds)}; learns: {part['bar']})",
            "",
            "| method | " + " | ".join(f"seed {s}" for s in seeds) + " | mean | learns |",
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
            learns = part["learns"].get(key)
            verdict = "—" if learns is None else ("yes" if learns else "no")
            label = LABELS.get(key, key)
            lines.append(f"| {label} | " + " | ".join(cells) + f" | {m['mean']:.1f} | {verdict} |")
        d = part["dara_vs_maple"]
        if d:
            per = ", ".join(f"seed {s}: {x:+.1f}" for s, x in zip(seeds, d["deltas"], strict=True))
            lines += ["", f"{LABELS[d['dara']]} − {LABELS[d['maple']]} (normalised): mean {d['mean']:+.1f} "
                      f"({per}): {d['verdict']}."]  # fmt: skip
        lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    res = summarise(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE / "runs")
    print(table(res), end="")
