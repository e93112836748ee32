"""Writing a report: ``report.md`` (one table per env), ``summary.json`` and one
``curves_<env>.png`` per env. Files are written atomically (temp file + ``os.replace``)."""

from __future__ import annotations

import json
import math
import os
import re
import tempfile
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rllib_asor.report.results import Trial
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


def atomic_write(path: Path, data: bytes) -> None:
    """Write `data` to `path` via a temp file and `os.replace` (no half-written file)."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp's 0600 -> the usual mode of a new file
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _jsonable(obj: Any) -> Any:
    """NaN/inf -> None, recursively, so summary.json is strict JSON."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    return obj


def _curve(trial: Trial, metric: str, x: str) -> tuple[np.ndarray, np.ndarray]:
    xs, ys = trial.series(x), trial.series(metric)
    ok = np.isfinite(xs) & np.isfinite(ys)
    order = np.argsort(xs[ok], kind="stable")  # np.interp needs increasing x
    return xs[ok][order], ys[ok][order]


def plot_env(report: Report, env: str, path: Path) -> None:
    """One PNG: mean ± std across seeds per method over `report.x`, for one env."""
    import matplotlib

    matplotlib.use("Agg")
    import io

    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5), dpi=100)
    try:
        for g in (g for g in report.groups if g.env == env):
            curves = [
                _curve(t, report.metric, report.x)
                for t in report.trials
                if t.env == env and t.method == g.method
            ]
            curves = [(cx, cy) for cx, cy in curves if cx.size]
            if not curves:
                continue
            hi = max(float(cx.max()) for cx, _ in curves)
            lo = min(float(cx.min()) for cx, _ in curves)
            grid = np.linspace(lo, hi, 200) if hi > lo else np.array([lo])
            # Each seed is interpolated only inside the range it reached (no extrapolation).
            ys = np.array(
                [
                    np.where(
                        (grid >= cx.min()) & (grid <= cx.max()), np.interp(grid, cx, cy), np.nan
                    )
                    for cx, cy in curves
                ]
            )
            count = np.isfinite(ys).sum(axis=0)
            keep = count > 0
            with warnings.catch_warnings():  # all-NaN grid columns are dropped by `keep`
                warnings.simplefilter("ignore", RuntimeWarning)
                mean = np.nanmean(ys, axis=0)
                std = np.nan_to_num(np.nanstd(ys, axis=0, ddof=1))  # sample std, as in the table
            label = f"{g.method} (n={g.n})"
            if keep.sum() == 1:
                ax.errorbar(grid[keep], mean[keep], yerr=std[keep], fmt="o", label=label, capsize=3)
            else:
                (line,) = ax.plot(grid[keep], mean[keep], label=label)
                ax.fill_between(
                    grid[keep],
                    (mean - std)[keep],
                    (mean + std)[keep],
                    color=line.get_color(),
                    alpha=0.2,
                    linewidth=0,
                )
        ax.set_title(f"{env}: {report.metric}")
        ax.set_xlabel(report.x)
        ax.set_ylabel(f"{report.metric} (mean ± std over seeds)")
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize="small")
        fig.tight_layout()
        buf = io.BytesIO()
        fig.savefig(buf, format="png")
    finally:
        plt.close(fig)
    atomic_write(path, buf.getvalue())


def render_markdown(report: Report, results_dir: Path, plots: dict[str, str]) -> str:
    """The report as markdown: one table per env, its curve, the trials, notes."""
    out = [
        "# Training report",
        "",
        f"- results: `{results_dir}`",
        f"- metric: `{report.metric}`; final value per trial = mean of its last "
        f"{report.last_n} iteration(s)",
        "- per method: trials (seeds), final mean ± std (sample std), 95% bootstrap CI of the "
        "mean (BCa, 5,000 resamples), IQM (25% trimmed mean), env steps "
        f"(mean final `{report.x}`)",
        "",
    ]
    for env in sorted({g.env for g in report.groups}):
        out += [f"## {env}", ""]
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
    root = Path(results_dir).expanduser()
    report = summarize(root, metric, x, last_n, group_by, columns)
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
            }
            for g in report.groups
        ],
        "notes": report.notes,
    }
    atomic_write(
        out / "summary.json",
        (json.dumps(_jsonable(summary), indent=2, allow_nan=False) + "\n").encode(),
    )
    md = out / "report.md"
    atomic_write(md, render_markdown(report, root, plots).encode())
    return md
