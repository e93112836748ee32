"""Summarise the MAPLE Hopper study (run.py): the table beside the paper and the fixed rule.

Reads RUNS/*.json; writes table.md and summary.json beside RUNS and prints the table. The rule
(studies/maple_hopper/README.md, fixed before any run):
Δ = score(MAPLE+ASOR) − score(MAPLE) per (dataset, seed), pooled over Hopper-medium and
Hopper-random; its mean with a 95 % BCa bootstrap interval (`rllib_asor.report.paired`:
scipy, 5,000 resamples, fixed seed) and the Wilcoxon signed-rank p.
- reproduced: the interval lies above 0;
- not reproduced at the paper's size: the interval lies below +13 points (half the paper's mean
  Hopper gain, (+33 + +20) / 2 = +26.5);
- otherwise inconclusive.
Applied to the paper preset (primary) and the robust default; "which preset the evidence
favours": the same interval on Δ(robust − paper). MOPO and CQL are references (no test; the
rows MAPLE − MOPO and MAPLE − CQL check the base, the second added after the rule).
A comparison with fewer pairs than it can have (the rule's 6; 5 for the methods that started
after the data was committed, since medium seed 0 ran on an earlier build) is labelled interim:
a bootstrap interval over 3-4 pairs lies above 0 whenever all Δ are positive (with no effect:
1 chance in 8 or 16), so an interim interval is not the rule's verdict (label added after the
robust form's 4th pair).
One exploratory row, chosen after 3 pairs and not part of the rule: the same Δ on the mean of
each run's evaluations in the second half of training (`late_score`), because single end points
moved by ±20 within a run.

    .venv/bin/python studies/maple_hopper/summarise.py
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from studies.lib.run_files import read_run, run_paths

HERE = Path(__file__).resolve().parent
PAPER = {  # Table 1 of the paper (normalised ×100), Hopper rows
    "medium": {"maple": 38.0, "maple_asor_paper": 71.0},
    "random": {"maple": 12.0, "maple_asor_paper": 32.0},
}
PAPER_GAIN = 26.5
ORDER = ("maple", "maple_asor_paper", "maple_asor", "mopo", "cql")


def load(runs: Path) -> dict[tuple[str, str], dict[int, dict[str, Any]]]:
    """{(dataset, method): {seed: run}}."""
    out: dict[tuple[str, str], dict[int, dict[str, Any]]] = {}
    prints: dict[tuple[str, int], dict[str, list[str]]] = {}
    for path in run_paths(runs):
        r = read_run(path)
        out.setdefault((r["dataset"], r["method"]), {})[int(r["seed"])] = r
        fp = r.get("data_fingerprint", "unrecorded")
        prints.setdefault((r["dataset"], int(r["seed"])), {}).setdefault(fp, []).append(path.name)
    # a data rebuild is not bit-identical (medium seed 0 ran on an earlier build than the
    # committed data/, and --data may point at another): the runs of one (dataset, seed) (a
    # pair, and the ensemble they share) must have trained on the same rows; different seeds
    # may come from different builds, like any other seed-level randomness.
    mixed = {f"{ds}/{seed}": fps for (ds, seed), fps in prints.items() if len(fps) > 1}
    if mixed:
        raise SystemExit(f"runs of one (dataset, seed) trained on different data: {mixed}")
    return out


def verdict(lo: float, hi: float, small: float = PAPER_GAIN / 2) -> str:
    if np.isnan(lo):
        return "not enough pairs"
    if lo > 0:
        return "reproduced (interval above 0)"
    if hi < small:
        return f"not reproduced at the paper's size (interval below +{small:.1f})"
    return "inconclusive"


def compare(lo: float, hi: float, a: str, b: str) -> str:
    if np.isnan(lo):
        return "not enough pairs"
    if lo > 0:
        return f"{a} higher"
    if hi < 0:
        return f"{b} higher"
    return "no difference detectable"


def late_score(run: dict[str, Any]) -> float:
    """The mean of a run's evaluations after half its iterations (the curve's points there;
    the first runs' curves also list the iterations without an evaluation, as NaN)."""
    late = [
        c["score"]
        for c in run["curve"]
        if c["iteration"] > run["iters"] / 2 and np.isfinite(c["score"])
    ]
    return float(np.mean(late)) if late else float("nan")


def paired(
    data: dict, a: str, b: str, planned: int, claim: bool = True, metric: str = "score"
) -> dict[str, Any]:
    """Δ = a − b over the (dataset, seed) pairs both have (`rllib_asor.report.paired`: BCa
    interval of the mean, Wilcoxon p), with this study's verdict, marked interim below
    `planned` pairs. `metric`: "score" (the rule's final score) or "late_score"."""
    from rllib_asor.report.paired import paired_difference

    value = late_score if metric == "late_score" else (lambda r: r["score"])
    base, treat = {}, {}
    for (ds, m), seeds in data.items():
        for s, r in seeds.items():
            if m == a:
                treat[(ds, s)] = value(r)
            elif m == b:
                base[(ds, s)] = value(r)
    if not base.keys() & treat.keys():
        return {
            "a": a,
            "b": b,
            "metric": metric,
            "pairs": [],
            "mean": float("nan"),
            "bca95": [float("nan")] * 2,
            "p": float("nan"),
            "verdict": "not enough pairs",
        }
    res = paired_difference(base, treat, baseline_name=b, treatment_name=a, metric=metric)
    lo, hi = res.ci_low, res.ci_high
    if res.pairs < 3:
        lo = hi = float("nan")
    label = verdict(lo, hi) if claim else compare(lo, hi, a, b)
    if np.isfinite(lo) and res.pairs < planned:  # an interval, on fewer pairs than planned
        label = f"interim, {res.pairs} of {planned} pairs: {label}"
    return {
        "a": a,
        "b": b,
        "metric": metric,
        "pairs": [
            {"dataset": k[0], "seed": k[1], "delta": d}
            for k, d in zip(res.seeds, res.diffs, strict=True)
        ],
        "mean": res.diff_mean,
        "bca95": [lo, hi],
        "p": res.p_value,
        "verdict": label,
    }


def summarise(runs: Path) -> dict[str, Any]:
    data = load(runs)
    rows = []
    for (ds, m), seeds in sorted(data.items(), key=lambda kv: (kv[0][0], ORDER.index(kv[0][1]))):
        scores = [r["score"] for r in seeds.values()]
        per_dyn = {
            d: [r["final"][d]["normalized_score"] for r in seeds.values()]
            for d in ("original", "body_mass", "density_10")
        }
        rows.append(
            {
                "dataset": ds,
                "method": m,
                "seeds": sorted(seeds),
                "score_mean": float(np.mean(scores)),
                "score_std": float(np.std(scores, ddof=1)) if len(scores) > 1 else 0.0,
                "per_dynamics": {d: float(np.mean(v)) for d, v in per_dyn.items()},
                "gradient_steps": next(iter(seeds.values()))["gradient_steps"],
                "wall_s_mean": float(np.mean([r["wall_s"] for r in seeds.values()])),
                "paper": PAPER.get(ds, {}).get(m),
            }
        )
    return {
        "rows": rows,
        "asor_paper_vs_maple": paired(data, "maple_asor_paper", "maple", 6),
        "asor_robust_vs_maple": paired(data, "maple_asor", "maple", 5),
        "robust_vs_paper": paired(data, "maple_asor", "maple_asor_paper", 5, claim=False),
        "maple_vs_mopo": paired(data, "maple", "mopo", 5, claim=False),
        "maple_vs_cql": paired(data, "maple", "cql", 5, claim=False),
        "asor_paper_vs_maple_late": paired(
            data, "maple_asor_paper", "maple", 6, claim=False, metric="late_score"
        ),
    }


def table(res: dict[str, Any]) -> str:
    lines = [
        "| dataset | method | seeds | gradient steps | original | body_mass | density_10 | "
        "mean score | paper (Table 1) | wall s / run |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in res["rows"]:
        pd = r["per_dynamics"]
        paper = "" if r["paper"] is None else f"{r['paper']:.0f}"
        lines.append(
            f"| {r['dataset']} | {r['method']} | {len(r['seeds'])} | {r['gradient_steps']:,} | "
            f"{pd['original']:.1f} | {pd['body_mass']:.1f} | {pd['density_10']:.1f} | "
            f"{r['score_mean']:.1f} ± {r['score_std']:.1f} | {paper} | {r['wall_s_mean']:.0f} |"
        )
    lines += [
        "",
        "| comparison | score | pairs | mean Δ | 95 % BCa | Wilcoxon p | verdict |",
        "|---|---|---|---|---|---|---|",
    ]
    for c in (v for k, v in res.items() if k != "rows"):  # the comparisons, in summarise's order
        lo, hi = c["bca95"]
        score = "late (exploratory)" if c["metric"] == "late_score" else "final (the rule)"
        lines.append(
            f"| {c['a']} − {c['b']} | {score} | {len(c['pairs'])} | {c['mean']:+.1f} | "
            f"[{lo:+.1f}, {hi:+.1f}] | {c['p']:.2f} | {c['verdict']} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--runs", default=str(HERE / "runs"))
    args = p.parse_args()
    runs = Path(args.runs)
    res = summarise(runs)
    md = table(res)
    (runs.parent / "table.md").write_text(md)  # beside the runs folder
    (runs.parent / "summary.json").write_text(json.dumps(res, indent=1))
    print(md)


if __name__ == "__main__":
    main()
