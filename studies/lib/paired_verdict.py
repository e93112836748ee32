"""A paired study's table and its fixed rule's verdict: each arm against one baseline, seed by
seed, on one per-run metric, decided only once the arm and the baseline both have every planned
seed. A study's summarise.py states its rule as a `PairedStudy` (studies/race_scale,
race_scale_steps, race_scale_budget, race_scale_2m, race_scale_rollout_2m); the readings
reported beside a rule, deciding nothing (declining runs, a descriptive paired difference),
are the functions at the end."""

from __future__ import annotations

import statistics
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rllib_asor.report.paired import paired_difference
from studies.lib.common import declines, write_summary
from studies.lib.compare import load_metric_by_seed
from studies.lib.run_files import read_runs


def verdict(low: float, high: float, margin: float, pairs: int) -> str:
    """'as good' iff the interval's lower end is above `margin`, 'worse' iff its upper end is
    below 0, otherwise undecided."""
    if low > margin:
        return "as good"
    if high < 0:
        return "worse"
    return f"not decided at {pairs} pairs"


def summarise(
    study_dirs: Sequence[Path],
    metric: str,
    baseline: str,
    arms: Sequence[str],
    seeds: Sequence[int],
    margin: float,
) -> dict[str, Any]:
    """Per method: runs, mean ± sd, seeds at 0, mean training wall time; per arm: the paired
    difference arm − baseline and the verdict once both have every seed in `seeds`."""
    by_seed = load_metric_by_seed(list(study_dirs), metric)
    walls: dict[str, list[float]] = {}
    for folder in study_dirs:
        for run in read_runs(folder / "runs"):
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
        if m == baseline or m in arms
    }
    base = by_seed.get(baseline, {})
    out: dict[str, Any] = {"methods": methods, "arms": {}}
    for arm in arms:
        mine = by_seed.get(arm, {})
        if set(base) >= set(seeds) and set(mine) >= set(seeds):
            p = paired_difference(
                {s: base[s] for s in seeds}, {s: mine[s] for s in seeds},
                baseline_name=baseline, treatment_name=arm, metric=metric,
            )  # fmt: skip
            out["arms"][arm] = {
                "paired": p.to_json(),
                "verdict": verdict(p.ci_low, p.ci_high, margin, len(seeds)),
            }
        else:
            have = {m: len(set(v) & set(seeds)) for m, v in ((arm, mine), (baseline, base))}
            runs = ", ".join(f"{m} {n} of {len(seeds)}" for m, n in have.items())
            out["arms"][arm] = {
                "verdict": f"not yet: {runs} runs (the rule decides once all exist)"
            }
    return out


def table(res: dict[str, Any], baseline: str, wall_note: str) -> str:
    """Markdown: one row per method, one paired row per decided arm, one verdict per arm."""
    lines = [
        "| file | runs | success on unseen courses (mean ± sd) | seeds at 0 | "
        f"training wall s ({wall_note}) |",
        "|---|---|---|---|---|",
    ]
    for m, v in res["methods"].items():
        lines.append(
            f"| {m} | {v['runs']} | {v['mean']:.3f} ± {v['std']:.3f} | {v['dead']} | "
            f"{v['train_wall_s']:.0f} |"
        )
    decided = {a: r for a, r in res["arms"].items() if "paired" in r}
    if decided:
        lines += [
            "",
            f"| arm − {baseline} | pairs | mean diff | 95 % BCa | Wilcoxon p (two-sided) |",
            "|---|---|---|---|---|",
        ]
        for arm, r in decided.items():
            p = r["paired"]
            lines.append(
                f"| {arm} | {p['pairs']} | {p['diff_mean']:+.3f} | {p['ci_low']:+.3f} … "
                f"{p['ci_high']:+.3f} | {p['p_value']:.2f} |"
            )
    lines.append("")
    for arm, r in res["arms"].items():
        lines.append(f"Verdict for {arm} (README.md's rule): **{r['verdict']}**  ")
    return "\n".join(lines).rstrip() + "\n"


@dataclass(frozen=True)
class PairedStudy:
    """A paired study's fixed rule as data: its `arms` against `baseline`, read from the study's
    own runs and those of the sibling study folders `also` (where the baseline's runs live)."""

    arms: tuple[str, ...]
    baseline: str = "today"
    also: tuple[str, ...] = ()
    metric: str = "eval.per_map.*.success"
    seeds: range = range(20)
    margin: float = -0.10
    """'as good' iff the 95 % BCa interval's lower end is above this."""
    wall: str = "2-core machine, 2 runs at once"
    declining: tuple[tuple[str, str], ...] = ()
    """Read beside the rule: (study folder, "" for this one; method) whose runs' declining
    seeds are listed (`declining_seeds`)."""
    beside: tuple[str, str, str] | None = None
    """Read beside the rule: (study folder, baseline, treatment): `treatment − baseline` over
    their shared seeds (`descriptive_pair`), e.g. a method at 2M against itself at 500k."""
    beside_at: str = "500k"
    """What `beside`'s baseline is, in its line and summary key ("today-2m − today (500k)")."""

    def summarise(self, runs: Path) -> dict[str, Any]:
        """The study's summary from its runs folder (`pages` and `cli` call it)."""
        studies = runs.parent.parent
        folders = [runs.parent, *(studies / name for name in self.also)]
        res = summarise(folders, self.metric, self.baseline, self.arms, self.seeds, self.margin)
        if self.declining:
            res["declining"] = {
                method: declining_seeds(studies / (folder or runs.parent.name) / "runs", method)
                for folder, method in self.declining
            }
        if self.beside:
            folder, baseline, treatment = self.beside
            res[self._beside_key] = descriptive_pair(
                [runs.parent, studies / folder], self.metric, baseline, treatment
            )
        return res

    @property
    def _beside_key(self) -> str:
        """`beside`'s summary key: "today_2m_vs_500k" for treatment today-2m."""
        assert self.beside is not None
        return f"{self.beside[2].replace('-', '_')}_vs_{self.beside_at}"

    def table(self, res: dict[str, Any]) -> str:
        """The rule's table, then what `declining` and `beside` read beside it."""
        lines = [table(res, self.baseline, self.wall)]
        if self.declining:
            lines += declining_table(res["declining"])
        if self.beside:
            _, baseline, treatment = self.beside
            label = f"{treatment} − {baseline} ({self.beside_at})"
            lines += ["", descriptive_line(res[self._beside_key], label)]
        return "\n".join(lines) + ("\n" if len(lines) > 1 else "")

    def cli(self, default_folder: Path) -> None:
        """The study's `summarise.py` as a script: STUDY_DIR (argv[1], else `default_folder`)
        → its summary.json and table.md, and the table printed."""
        folder = Path(sys.argv[1]) if len(sys.argv) > 1 else default_folder
        print(write_summary(folder, self.summarise, self.table))


def declining_seeds(runs: Path, method: str) -> dict[str, Any]:
    """`method`'s finished runs in the runs folder `runs`, and the seeds among them whose
    training success declines (`studies.lib.common.declines`), read beside a rule."""
    done = [r for r in read_runs(runs) if r["method"] == method]
    return {"runs": len(done), "seeds": sorted(r["seed"] for r in done if declines(r["curve"]))}


def declining_table(declining: dict[str, dict[str, Any]]) -> list[str]:
    """Markdown rows: per method its runs and declining seeds."""
    lines = [
        "| method | runs | declining (README.md's reading) | seeds |",
        "|---|---|---|---|",
    ]
    for method, d in declining.items():
        seeds = ", ".join(map(str, d["seeds"])) or "–"
        lines.append(f"| {method} | {d['runs']} | {len(d['seeds'])} | {seeds} |")
    return lines


def descriptive_pair(
    study_dirs: Sequence[Path], metric: str, baseline: str, treatment: str
) -> dict[str, Any]:
    """`treatment − baseline` over the seeds both have (read from `study_dirs`), as
    `paired_difference`'s JSON; only {"pairs": n} below 3 pairs (no BCa interval there)."""
    by_seed = load_metric_by_seed(list(study_dirs), metric)
    then, now = by_seed.get(baseline, {}), by_seed.get(treatment, {})
    seeds = sorted(set(now) & set(then))
    if len(seeds) < 3:
        return {"pairs": len(seeds)}
    return paired_difference(
        {s: then[s] for s in seeds}, {s: now[s] for s in seeds},
        baseline_name=baseline, treatment_name=treatment, metric=metric,
    ).to_json()  # fmt: skip


def descriptive_line(p: dict[str, Any], label: str) -> str:
    """One line for a `descriptive_pair` result, named `label` ("a − b (500k)")."""
    if "diff_mean" not in p:
        return f"{label}: {p['pairs']} pairs so far"
    return (
        f"{label}, descriptive: {p['pairs']} pairs, {p['diff_mean']:+.3f}, "
        f"95 % BCa {p['ci_low']:+.3f} … {p['ci_high']:+.3f}"
    )
