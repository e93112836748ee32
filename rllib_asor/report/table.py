"""`rllib compare --table`: the paper's layout: tasks (envs) as rows, methods (groups of trials
that differ in the seed only) as columns, each cell the mean score over seeds ± the half-width
of its 95 % bootstrap interval (`stats.bootstrap_ci`) and the seed count, the best mean of a row
in bold (markdown). Scores as `rllib compare` reads them (`scores.choose_source` per env); a
method without a finite score that way (MAPLE and MOPO evaluate themselves, outside RLlib's
evaluation env runners) is scored by its own evaluation (`OWN_EVALUATION`), any other method
without a score that way by the best score its own trials have (e.g. the training return beside
GARAT, which alone evaluates, in its target). Under the table, which score each column shows."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import numpy as np

from rllib_asor.report.compare import load_trials
from rllib_asor.report.grouping import group_trials
from rllib_asor.report.results import Trial
from rllib_asor.report.scores import Source, choose_source, score
from rllib_asor.report.stats import bootstrap_ci

OWN_EVALUATION = (
    Source(
        "maple-evaluation",
        "evaluation/mean/normalized_score",
        "D4RL-normalised score of its own evaluation (MAPLE family, BCO, SOIL; greedy, each "
        "dynamics of the data, their mean; `evaluation/mean/normalized_score`, last value)",
    ),
    Source(
        "maple-evaluation",
        "evaluation/mean/return_mean",
        "return of its own evaluation (MAPLE family, BCO, SOIL; greedy, each dynamics of the "
        "data, their mean; `evaluation/mean/return_mean`, last value; the data has no reference "
        "returns)",
    ),
)
"""Scores of methods that evaluate themselves (MAPLE, MOPO and their +DARA/+ASOR; offline BCO
and SOIL log the same keys), in order of preference: the first that every trial of the group
has."""


def _scores(trials: list[Trial], source: Source, last_n: int) -> list[float]:
    return [v for v in (score(t, source, last_n) for t in trials) if math.isfinite(v)]


def _own_source(trials: list[Trial]) -> Source | None:
    return next((s for s in OWN_EVALUATION if all(t.has(s.key) for t in trials)), None)


def table_cells(
    results_dirs: Sequence[str | os.PathLike[str]], metric: str | None = None, last_n: int = 1
) -> tuple[list[str], list[str], dict[tuple[str, str], list[float]], dict[tuple[str, str], str]]:
    """(envs, method labels, {(env, label): finite scores per seed}, {(env, label): what the
    score is}); ValueError without trials."""
    notes: list[str] = []
    trials = load_trials(results_dirs, notes)
    if not trials:
        raise ValueError(f"no Tune trials under {', '.join(map(str, results_dirs))}")
    groups = group_trials(trials)
    cells: dict[tuple[str, str], list[float]] = {}
    sources: dict[tuple[str, str], str] = {}
    for env in sorted({g.env for g in groups}):
        mine = [g for g in groups if g.env == env]
        source = choose_source([t for g in mine for t in g.trials], metric)
        for g in mine:
            used, values = source, _scores(g.trials, source, last_n)
            own = None if metric or values else _own_source(g.trials)
            if own is None and not metric and not values:  # e.g. only GARAT evaluates in its
                own = choose_source(g.trials)  # target: the others keep their own score
            if own is not None:
                used, values = own, _scores(g.trials, own, last_n)
            cells[(env, g.label)] = values
            sources[(env, g.label)] = used.description if values else "no score recorded"
    envs = sorted({e for e, _ in cells})
    labels = sorted({label for _, label in cells})
    return envs, labels, cells, sources


def _cell(values: list[float]) -> tuple[float, str]:
    if not values:
        return -math.inf, "—"
    mean = float(np.mean(values))
    lo, hi = bootstrap_ci(values)
    half = (hi - lo) / 2 if math.isfinite(lo) and math.isfinite(hi) else math.nan
    spread = f" ± {half:.3g}" if math.isfinite(half) else ""
    return mean, f"{mean:.3g}{spread} (n={len(values)})"


def render_table(
    envs: list[str],
    labels: list[str],
    cells: dict[tuple[str, str], list[float]],
    sources: dict[tuple[str, str], str] | None = None,
) -> str:
    """A markdown table: one row per env, one column per method, the best mean in bold; with
    `sources`, a list under it of what each column's score is."""
    lines = ["| task | " + " | ".join(labels) + " |", "|---" * (len(labels) + 1) + "|"]
    for env in envs:
        row = {label: _cell(cells.get((env, label), [])) for label in labels}
        best = max((m for m, _ in row.values()), default=-math.inf)
        texts = [
            f"**{text}**" if math.isfinite(mean) and mean == best else text
            for mean, text in row.values()
        ]
        lines.append(f"| {env} | " + " | ".join(texts) + " |")
    if sources:
        by: dict[str, list[str]] = {}
        for env in envs:
            for label in labels:
                if (env, label) in sources:
                    name = label if len(envs) == 1 else f"{label} on {env}"
                    by.setdefault(sources[(env, label)], []).append(name)
        lines += ["", "Scores:"] + [f"- {', '.join(names)}: {text}" for text, names in by.items()]
    return "\n".join(lines) + "\n"
