"""`rllib compare --table`: the paper's layout: tasks (envs) as rows, methods (groups of trials
that differ in the seed only) as columns, each cell the mean score over seeds ± the half-width
of its 95 % bootstrap interval (`stats.bootstrap_ci`) and the seed count, the best mean of a row
in bold (markdown). Scores as `rllib compare` reads them (`scores.choose_source` per env)."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import numpy as np

from rllib_asor.report.compare import load_trials
from rllib_asor.report.grouping import group_trials
from rllib_asor.report.scores import choose_source, score
from rllib_asor.report.stats import bootstrap_ci


def table_cells(
    results_dirs: Sequence[str | os.PathLike[str]], metric: str | None = None, last_n: int = 1
) -> tuple[list[str], list[str], dict[tuple[str, str], list[float]]]:
    """(envs, method labels, {(env, label): finite scores per seed}); ValueError without
    trials."""
    notes: list[str] = []
    trials = load_trials(results_dirs, notes)
    if not trials:
        raise ValueError(f"no Tune trials under {', '.join(map(str, results_dirs))}")
    groups = group_trials(trials)
    cells: dict[tuple[str, str], list[float]] = {}
    for env in sorted({g.env for g in groups}):
        mine = [g for g in groups if g.env == env]
        source = choose_source([t for g in mine for t in g.trials], metric)
        for g in mine:
            values = [score(t, source, last_n) for t in g.trials]
            cells[(env, g.label)] = [v for v in values if math.isfinite(v)]
    envs = sorted({e for e, _ in cells})
    labels = sorted({label for _, label in cells})
    return envs, labels, cells


def _cell(values: list[float]) -> tuple[float, str]:
    if not values:
        return -math.inf, "—"
    mean = float(np.mean(values))
    lo, hi = bootstrap_ci(values)
    half = (hi - lo) / 2 if math.isfinite(lo) and math.isfinite(hi) else math.nan
    spread = f" ± {half:.3g}" if math.isfinite(half) else ""
    return mean, f"{mean:.3g}{spread} (n={len(values)})"


def render_table(
    envs: list[str], labels: list[str], cells: dict[tuple[str, str], list[float]]
) -> str:
    """A markdown table: one row per env, one column per method, the best mean in bold."""
    lines = ["| task | " + " | ".join(labels) + " |", "|---" * (len(labels) + 1) + "|"]
    for env in envs:
        row = {label: _cell(cells.get((env, label), [])) for label in labels}
        best = max((m for m, _ in row.values()), default=-math.inf)
        texts = [
            f"**{text}**" if math.isfinite(mean) and mean == best else text
            for mean, text in row.values()
        ]
        lines.append(f"| {env} | " + " | ".join(texts) + " |")
    return "\n".join(lines) + "\n"
