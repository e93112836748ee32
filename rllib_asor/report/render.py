"""Writing a report: ``report.md`` (one table per env), ``summary.json`` and one
``curves_<env>.png`` per env. Files are written atomically (temp file + ``os.replace``)."""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Sequence
from pathlib import Path

from rllib_asor.report.files import atomic_write, jsonable
from rllib_asor.report.lead import paired_lead
from rllib_asor.report.plots import plot_curves
from rllib_asor.report.stats import BOOTSTRAP_RESAMPLES
from rllib_asor.report.summary import DEFAULT_METRIC, DEFAULT_X, Report, summarize

# --------------------------------------------------------------------------- writing


def _fmt(v: float) -> str:
    if not math.isfinite(v):
        return "n/a"
    if v == 0 or 0.01 <= abs(v) < 1e6:
        return f"{v:.2f}"
    return f"{v:.3g}"


def _pm(mean: float, std: float) -> str:
    return f"{_fmt(mean)} ± {_fmt(std)}" if math.isfinite(mean) else "n/a"


def _slug(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_") or "env"


def plot_env(report: Report, env: str, path: Path) -> None:
    """One PNG for one env: per group, the mean over seeds on a grid of env steps that every
    seed reached, with a 95% BCa band (`rllib_asor.report.plots.plot_curves`)."""
    groups = [
        (g.method, [t for t in report.trials if t.env == env and t.method == g.method])
        for g in report.groups
        if g.env == env
    ]
    plot_curves(
        groups, report.metric, report.x, path, f"{env}: {report.metric}", report.notes.append
    )


def render_markdown(report: Report, results_dir: Path, plots: dict[str, str]) -> str:
    """The report as markdown: one table per env, its curve, the trials, notes."""
    out = ["# Training report", ""]
    if report.lead:
        out += [*report.lead, ""]
    health = [g.asor_health for g in report.groups if g.asor_health]
    if health:
        out += ["ASOR looks inert:", "", *(f"- {h}" for h in health), ""]
    out += [
        f"- results: `{results_dir}`",
        f"- metric: `{report.metric}`; final value per trial = mean of its last "
        f"{report.last_n} iteration(s)",
        "- per group (trials whose settings differ in the seed only): trials (seeds), final "
        "mean ± std (sample std), 95% bootstrap CI of the mean (scipy BCa, "
        f"{BOOTSTRAP_RESAMPLES:,} resamples), IQM (25% trimmed mean), env steps "
        f"(mean final `{report.x}`)",
        "- curves: each seed interpolated onto a grid of x values that every seed of the group "
        "reached (a curve ends where its shortest seed ends); mean over seeds with a 95% BCa band",
        "- training returns explore; for a paired comparison on evaluation returns use "
        "`rllib compare` (docs/report.md)",
        "",
    ]
    for env in sorted({g.env for g in report.groups}):
        out += [f"## {env}", ""]
        keyed = [g for g in report.groups if g.env == env and g.settings]
        if keyed:
            out += ["Settings that define the groups (the seed aside):", ""]
            out += [
                f"- {g.method}: " + ", ".join(f"`{k}`={v}" for k, v in g.settings.items())
                for g in keyed
            ]
            out.append("")
        head = ["method", "trials", "final mean ± std", "95% CI", "IQM", "env steps"]
        head += [f"`{c}`" for c in report.columns]
        out += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for g in (g for g in report.groups if g.env == env):
            ci = f"[{_fmt(g.ci_low)}, {_fmt(g.ci_high)}]" if g.n > 1 else "n/a (1 trial)"
            cells = [
                g.method,
                str(g.n),
                _pm(g.mean, g.std),
                ci,
                _fmt(g.iqm),
                f"{g.env_steps:,.0f}" if math.isfinite(g.env_steps) else "n/a",
            ]
            cells += [_pm(*g.extra[c]) for c in report.columns]
            out.append("| " + " | ".join(cells) + " |")
        if env in plots:
            out += ["", f"![{env} learning curves]({plots[env]})"]
        out.append("")
    out += [
        "## Trials",
        "",
        "| env | method | trial | iterations | final |",
        "|---|---|---|---|---|",
    ]
    for t in sorted(report.trials, key=lambda t: (t.env, t.method, str(t.path))):
        rel = os.path.relpath(t.path, results_dir)
        out.append(
            f"| {t.env} | {t.method} | `{rel}` | {len(t.rows)} | "
            f"{_fmt(t.final(report.metric, report.last_n))} |"
        )
    if report.notes:
        out += ["", "## Notes", ""] + [f"- {n}" for n in report.notes]
    return "\n".join(out) + "\n"


def make_report(
    results_dir: str | os.PathLike[str],
    out_dir: str | os.PathLike[str] | None = None,
    metric: str = DEFAULT_METRIC,
    x: str = DEFAULT_X,
    last_n: int = 1,
    group_by: str | None = None,
    columns: Sequence[str] | None = None,
) -> Path:
    """Write report.md, summary.json and curves_<env>.png; return the report.md path.

    Raises ValueError for a missing directory, no results, or a metric no trial reports.
    """
    return write_report(results_dir, out_dir, metric, x, last_n, group_by, columns)[1]


def write_report(
    results_dir: str | os.PathLike[str],
    out_dir: str | os.PathLike[str] | None = None,
    metric: str = DEFAULT_METRIC,
    x: str = DEFAULT_X,
    last_n: int = 1,
    group_by: str | None = None,
    columns: Sequence[str] | None = None,
) -> tuple[Report, Path]:
    """`make_report`, returning the `Report` (its lead lines and ASOR health) too."""
    root = Path(results_dir).expanduser()
    report = summarize(root, metric, x, last_n, group_by, columns)
    report.lead = paired_lead(root)
    out = Path(out_dir).expanduser() if out_dir is not None else root / "report"
    out.mkdir(parents=True, exist_ok=True)
    plots: dict[str, str] = {}
    for env in sorted({g.env for g in report.groups}):
        name = f"curves_{_slug(env)}.png"
        plot_env(report, env, out / name)
        plots[env] = name
    summary = {
        "metric": report.metric,
        "x": report.x,
        "last_n": report.last_n,
        "groups": [
            {
                "env": g.env,
                "method": g.method,
                "n": g.n,
                "mean": g.mean,
                "std": g.std,
                "ci95": [g.ci_low, g.ci_high],
                "iqm": g.iqm,
                "env_steps": g.env_steps,
                "finals": g.finals,
                "extra": {k: list(v) for k, v in g.extra.items()},
                "settings": g.settings,
                "asor_health": g.asor_health,
            }
            for g in report.groups
        ],
        "lead": report.lead,
        "notes": report.notes,
    }
    atomic_write(
        out / "summary.json",
        (json.dumps(jsonable(summary), indent=2, allow_nan=False) + "\n").encode(),
    )
    md = out / "report.md"
    atomic_write(md, render_markdown(report, root, plots).encode())
    return report, md
