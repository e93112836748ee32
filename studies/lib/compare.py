"""Compare methods on one per-run metric: mean ± std, Δ vs a baseline with a 95% bootstrap CI,
and a one-sided Mann–Whitney U p-value for "method > baseline" (unpaired, seeds pooled).
The statistics are `rllib_asor.report.paired`'s (`unpaired_difference`, `paired_difference`,
the numbers `rllib compare` prints); this module reads run files and writes the tables.

    python -m studies.lib.compare --runs studies/out/lava --metric greedy_return_mean \\
        --baseline ppo --methods asor asor-paper [--out table.md] [--paired]

`--paired` compares seed by seed (only seeds run by both): the CI of the mean per-seed
difference and a one-sided Wilcoxon signed-rank p. Our benchmarks give a seed the same
initial weights and the same stream of env dynamics for every method, so where that shared
luck matters (Hopper: same-seed returns correlate at ~0.5) pairing narrows the interval.

Reads every run file of DIR/runs/ (`studies.lib.run_files`; fields "method", "seed" and the
metric). `--metric` is a dotted path into a run file; a `*` part averages over all keys at
that level, e.g. the race success rate (mean over the ten maps):
`--metric 'eval.per_map.*.success'`. Booleans count as 0/1 (`--metric escaped_trap`).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rllib_asor.report.paired import paired_difference, unpaired_difference
from studies.lib.run_files import read_run, run_paths


def _std(x: np.ndarray) -> float:
    return float(x.std(ddof=1)) if len(x) > 1 else 0.0


def sign_rule(deltas: Sequence[float], margin: float) -> int:
    """The studies' fixed-before-the-runs rule on paired differences: +1 if their mean is
    ≥ `margin` and every one is > 0, −1 for the mirror image, 0 otherwise."""
    mean = float(np.mean(deltas))
    if mean >= margin and all(d > 0 for d in deltas):
        return 1
    if mean <= -margin and all(d < 0 for d in deltas):
        return -1
    return 0


def compare_paired(baseline: dict[Any, float], treatment: dict[Any, float]) -> dict[str, float]:
    """Seed-by-seed comparison over the seeds in both: diff = mean of (treatment − baseline),
    its 95% interval over seeds (the project's BCa interval of a mean; NaN for one pair), and
    the one-sided Wilcoxon signed-rank p for treatment > baseline (1 when every difference is
    0). The numbers are `rllib compare`'s (`rllib_asor.report.paired.paired_difference`)."""
    if not set(baseline) & set(treatment):
        raise ValueError("compare_paired needs at least one seed run by both methods")
    r = paired_difference(baseline, treatment, alternative="greater")
    x = np.array([baseline[s] for s in r.seeds], dtype=float)
    y = np.array([treatment[s] for s in r.seeds], dtype=float)
    return {
        "n_pairs": r.pairs,
        "mean_baseline": r.baseline_mean,
        "std_baseline": _std(x),
        "mean_treatment": r.treatment_mean,
        "std_treatment": _std(y),
        "diff": r.diff_mean,
        "ci_low": r.ci_low,
        "ci_high": r.ci_high,
        "p_value": r.p_value,
    }


def metric_value(run: dict[str, Any], path: str) -> float:
    """The value at dotted `path` in `run`; a `*` part is the mean over that level's values."""
    parts = path.split(".")

    def get(node: Any, i: int) -> float:
        if i == len(parts):
            return float(node)
        if parts[i] == "*":
            values = node.values() if isinstance(node, dict) else node
            return float(np.mean([get(v, i + 1) for v in values]))
        key: Any = parts[i] if isinstance(node, dict) else int(parts[i])
        return get(node[key], i + 1)

    return get(run, 0)


def load_metric(dirs: Sequence[Path], metric: str) -> dict[str, list[float]]:
    """method → metric values over its runs in every DIR/runs/ (a (method, seed) seen
    twice counts once; runs without a finite metric are skipped; both warned on stderr)."""
    return {m: list(by_seed.values()) for m, by_seed in load_metric_by_seed(dirs, metric).items()}


def load_metric_by_seed(dirs: Sequence[Path], metric: str) -> dict[str, dict[Any, float]]:
    """method → {seed: metric value}, read like `load_metric`."""
    values: dict[str, dict[Any, float]] = {}
    seen: set[tuple[str, Any]] = set()
    for d in dirs:
        for p in run_paths(Path(d, "runs")):
            run = read_run(p)
            key = (run["method"], run.get("seed"))
            if key in seen:
                print(f"warning: {p}: {key} already read, skipped", file=sys.stderr)
                continue
            try:
                v = metric_value(run, metric)
            except (KeyError, IndexError, TypeError, ValueError):
                v = float("nan")
            if not np.isfinite(v):
                print(f"warning: {p}: no finite {metric!r}, skipped", file=sys.stderr)
                continue
            seen.add(key)
            values.setdefault(run["method"], {})[run.get("seed")] = v
    return values


def table(values: dict[str, list[float]], baseline: str, methods: Sequence[str]) -> str:
    """Markdown table: the baseline row, then one row per method compared with it."""
    lines = [
        "| method | n | mean ± std | Δ vs baseline | 95% CI of Δ | Mann–Whitney p (one-sided, >) |",
        "|---|---|---|---|---|---|",
    ]
    base = values.get(baseline, [])
    if base:
        x = np.asarray(base)
        lines.append(
            f"| {baseline} (baseline) | {len(x)} | {x.mean():.3f} ± {_std(x):.3f} | – | – | – |"
        )
    for name in methods:
        ys = values.get(name, [])
        if not ys:
            lines.append(f"| {name} | 0 | – | – | – | – |")
            continue
        if not base:
            y = np.asarray(ys)
            lines.append(f"| {name} | {len(y)} | {y.mean():.3f} ± {_std(y):.3f} | – | – | – |")
            continue
        c = unpaired_difference(base, ys)
        lines.append(
            f"| {name} | {c['n_treatment']} | {c['mean_treatment']:.3f} ± "
            f"{c['std_treatment']:.3f} | {c['diff']:+.3f} | [{c['ci_low']:+.3f}, "
            f"{c['ci_high']:+.3f}] | {c['p_value']:.3g} |"
        )
    return "\n".join(lines) + "\n"


def paired_table(values: dict[str, dict[Any, float]], baseline: str, methods: Sequence[str]) -> str:
    """Markdown table of `compare_paired` for each method against the baseline."""
    lines = [
        "| method | seeds in both | baseline mean ± std | method mean ± std | Δ (paired) "
        "| 95% CI of Δ | Wilcoxon p (one-sided, >) |",
        "|---|---|---|---|---|---|---|",
    ]
    base = values.get(baseline, {})
    for name in methods:
        mine = values.get(name, {})
        if not set(base) & set(mine):
            lines.append(f"| {name} | 0 | – | – | – | – | – |")
            continue
        c = compare_paired(base, mine)
        lines.append(
            f"| {name} | {c['n_pairs']} | {c['mean_baseline']:.3f} ± {c['std_baseline']:.3f} "
            f"| {c['mean_treatment']:.3f} ± {c['std_treatment']:.3f} | {c['diff']:+.3f} "
            f"| [{c['ci_low']:+.3f}, {c['ci_high']:+.3f}] | {c['p_value']:.3g} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--runs", nargs="+", type=Path, required=True, help="benchmark out dirs")
    parser.add_argument("--metric", default="greedy_return_mean", help="dotted path, `*` = mean")
    parser.add_argument("--baseline", default="ppo")
    parser.add_argument(
        "--methods", nargs="+", default=None, help="default: every method found but the baseline"
    )
    parser.add_argument("--out", type=Path, default=None, help="also write the table here")
    parser.add_argument("--paired", action="store_true", help="compare seed by seed")
    args = parser.parse_args(argv)
    by_seed = load_metric_by_seed(args.runs, args.metric)
    if args.baseline not in by_seed:
        print(
            f"warning: no runs of baseline {args.baseline!r} with {args.metric!r}", file=sys.stderr
        )
    methods = args.methods or sorted(m for m in by_seed if m != args.baseline)
    if args.paired:
        body = paired_table(by_seed, args.baseline, methods)
    else:
        values = {m: list(v.values()) for m, v in by_seed.items()}
        body = table(values, args.baseline, methods)
    md = (
        f"{args.metric}, vs {args.baseline}{' (paired by seed)' if args.paired else ''}:\n\n" + body
    )
    print(md)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
