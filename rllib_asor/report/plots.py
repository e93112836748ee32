"""Figures read at a glance: learning curves with a CI band over seeds on a common step grid,
the per-seed paired differences, and the returns per ``dynamics_id``. PNGs via matplotlib
(Agg), written atomically."""

from __future__ import annotations

import io
import textwrap
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rllib_asor.report.files import atomic_write
from rllib_asor.report.paired import ALPHA, Paired, decided
from rllib_asor.report.results import Trial
from rllib_asor.report.stats import bootstrap_ci_columns

GRID_POINTS = 100


def seed_curve(trial: Trial, metric: str, x: str) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) of one trial where both are finite, sorted by x."""
    xs, ys = trial.series(x), trial.series(metric)
    ok = np.isfinite(xs) & np.isfinite(ys)
    order = np.argsort(xs[ok], kind="stable")
    return xs[ok][order], ys[ok][order]


def common_grid(
    trials: Sequence[Trial], metric: str, x: str, points: int = GRID_POINTS
) -> tuple[np.ndarray, np.ndarray]:
    """Every seed interpolated onto one grid of x values that **every** seed reached.

    The grid spans [largest first x, smallest last x] over the seeds, so no point rests on fewer
    seeds than the others (a curve stops where the shortest seed stops; no extrapolation).
    Returns (grid, values[seed, point]); an empty grid when the seeds share no x range.
    """
    curves = [c for c in (seed_curve(t, metric, x) for t in trials) if c[0].size]
    if not curves:
        return np.empty(0), np.empty((0, 0))
    lo = max(float(cx[0]) for cx, _ in curves)
    hi = min(float(cx[-1]) for cx, _ in curves)
    if hi < lo:
        return np.empty(0), np.empty((len(curves), 0))
    grid = np.linspace(lo, hi, points) if hi > lo else np.array([lo])
    return grid, np.array([np.interp(grid, cx, cy) for cx, cy in curves])


def _save(fig: Any, path: Path) -> None:
    import matplotlib.pyplot as plt

    try:
        fig.tight_layout()
        buf = io.BytesIO()
        fig.savefig(buf, format="png")
    finally:
        plt.close(fig)
    atomic_write(path, buf.getvalue())


def _figure(width: float = 7, height: float = 4.5) -> tuple[Any, Any]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(figsize=(width, height), dpi=100)


def plot_curves(
    groups: Sequence[tuple[str, Sequence[Trial]]],
    metric: str,
    x: str,
    path: Path,
    title: str,
    note: Callable[[str], None] | None = None,
) -> None:
    """One PNG: per group its mean over seeds on the common grid, with a 95% BCa band."""
    fig, ax = _figure()
    for label, trials in groups:
        grid, ys = common_grid(trials, metric, x)
        if not grid.size:
            if note is not None:
                note(f"{title}: {label}: its seeds share no `{x}` range; no curve drawn")
            continue
        mean = ys.mean(axis=0)
        text = f"{label} (n={ys.shape[0]})"
        if grid.size == 1:
            ax.plot(grid, mean, "o", label=text)
            continue
        (line,) = ax.plot(grid, mean, label=text)
        if ys.shape[0] > 1:
            lo, hi = bootstrap_ci_columns(ys)
            ax.fill_between(grid, lo, hi, color=line.get_color(), alpha=0.2, linewidth=0)
    ax.set_title(title)
    ax.set_xlabel(x)
    ax.set_ylabel(f"{metric}\n(mean over seeds, 95% BCa band)")
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best", fontsize="small")
    _save(fig, path)


def plot_paired(result: Paired, path: Path) -> None:
    """One PNG: each seed's difference treatment − baseline, their mean and 95% interval."""
    fig, ax = _figure(6, 4)
    seeds = [str(s) for s in result.seeds]
    colors = ["tab:green" if d > 0 else "tab:red" if d < 0 else "tab:gray" for d in result.diffs]
    ax.bar(seeds, result.diffs, color=colors, alpha=0.7)
    ax.axhline(0, color="black", linewidth=0.8)
    ax.axhline(result.diff_mean, color="tab:blue", label=f"mean {result.diff_mean:+.4g}")
    if np.isfinite(result.ci_low):
        ax.axhspan(result.ci_low, result.ci_high, color="tab:blue", alpha=0.15, label="95% BCa")
    ax.set_xlabel("seed")
    ax.set_ylabel(f"{result.treatment} − {result.baseline}")
    ax.set_title(f"paired differences, p = {result.p_value:.3g} ({result.test})", fontsize="medium")
    ax.legend(loc="best", fontsize="small")
    _save(fig, path)


def plot_dynamics(results: Sequence[Paired], path: Path) -> tuple[list[str], str]:
    """One PNG: per dynamics id, both methods' mean return, labelled with the paired difference
    and ``*`` where `rllib_asor.report.paired.decided` (the table's rule: Holm-adjusted p < 5 %
    and the interval excludes 0); returns (the labels, the title)."""
    fig, ax = _figure(max(6.0, 0.9 * len(results) + 2), 4)
    ids = [f"{r.dynamics} (few)" if r.few_episodes else str(r.dynamics) for r in results]
    pos = np.arange(len(ids))
    for off, name, attr in ((-0.2, results[0].baseline, "baseline"),
                            (0.2, results[0].treatment, "treatment")):  # fmt: skip
        means = [getattr(r, f"{attr}_mean") for r in results]
        ax.bar(pos + off, means, width=0.4, alpha=0.6, label=name)
    ax.set_xticks(pos, ids)
    ax.set_xlabel("dynamics_id  (few: < 2 evaluation episodes behind a trial's score)")
    ax.set_ylabel(results[0].metric or "return")
    labels = [f"{r.diff_mean:+.3g}{'*' if decided(r) else ''}" for r in results]
    for p, r, label in zip(pos, results, labels, strict=True):
        top = max(r.baseline_mean, r.treatment_mean)
        ax.annotate(label, (p, top), ha="center", va="bottom", fontsize=8)
    withheld = next((r.withheld for r in results if r.withheld), None)
    title = (
        "mean return per dynamics (label: paired diff); * = decided: Holm-adjusted p < "
        f"{ALPHA:g} over {len(results)} dynamics and 95% CI excludes 0; others exploratory"
    )
    if withheld:
        title += f"\n{withheld}"
    ax.set_title(textwrap.fill(title, 90), fontsize="small")
    ax.grid(alpha=0.3, axis="y")
    ax.legend(loc="best", fontsize="small")
    _save(fig, path)
    return labels, title
