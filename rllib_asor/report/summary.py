"""Summarising trials per (env, group): final values, mean ± std, bootstrap CI, IQM, and the
extra race/... and asor/... columns. A group's trials differ in the seed only
(`rllib_asor.report.grouping`); its label is the method plus the settings that set it apart."""

from __future__ import annotations

import difflib
import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from rllib_asor.report.grouping import group_trials
from rllib_asor.report.health import group_health
from rllib_asor.report.results import Trial, find_trials
from rllib_asor.report.stats import bootstrap_ci, iqm, mean_std

DEFAULT_METRIC = "env_runners/episode_return_mean"
DEFAULT_X = "num_env_steps_sampled_lifetime"
FALLBACK_X = "training_iteration"

EXTRA_METRIC_RE = re.compile(r"(^|/)(race|asor)/")
"""Result keys eligible as extra columns: ``race/...`` and ``asor/...`` metrics."""

HEADLINE_ASOR = ("disc_acc", "aug_reward_mean", "bonus_share", "lambda", "active")
"""ASOR metrics shown by default (``--columns all`` shows every one); `bonus_share` is "the
bonus": the per-step amount ASOR adds, mean |Δr| ÷ the env reward's running RMS."""
HEADLINE_RACE = ("success_rate", "trapped_rate", "unnecessary_jump_rate", "goal_reward")
"""Race metrics shown by default: the paper's table, over all maps (per map: ``--columns all``)."""


@dataclass
class GroupStats:
    """Summary of one (env, method) group's final values."""

    env: str
    method: str
    n: int
    mean: float
    std: float
    ci_low: float
    ci_high: float
    iqm: float
    env_steps: float
    finals: list[float]
    extra: dict[str, tuple[float, float]] = field(default_factory=dict)
    """Extra column key -> (mean, std) over the group's trials that report it."""
    settings: dict[str, str] = field(default_factory=dict)
    """The params keys (and values) that tell this group apart from the env's other groups."""
    asor_health: str | None = None
    """One line when ASOR looks inert in the group's trials (`rllib_asor.report.health`)."""


@dataclass
class Report:
    """Everything `make_report` writes, for callers that want the numbers."""

    metric: str
    x: str
    last_n: int
    groups: list[GroupStats]
    trials: list[Trial]
    columns: list[str]
    notes: list[str]
    lead: list[str] = field(default_factory=list)
    """The report's first lines: the paired answer, or where it is (`rllib_asor.report.lead`)."""


# --------------------------------------------------------------------------- statistics


def _is_headline(key: str) -> bool:
    """A headline race/... or asor/... metric (over all maps and policies)."""
    parts = key.split("/")
    if len(parts) < 2:
        return False
    group, name = parts[-2], parts[-1]
    return (group == "race" and name in HEADLINE_RACE) or (
        group == "asor" and name in HEADLINE_ASOR
    )


def headline_columns(keys: Iterable[str]) -> list[str]:
    """The default extra columns: each headline metric once, from its shortest key (RLlib
    reports race metrics both as `race/...` and `env_runners/race/...`)."""
    best: dict[str, str] = {}
    for key in sorted(k for k in keys if _is_headline(k)):
        tail = "/".join(key.split("/")[-2:])
        if tail not in best or len(key) < len(best[tail]):
            best[tail] = key
    return sorted(best.values())


def summarize(
    results_dir: str | os.PathLike[str],
    metric: str = DEFAULT_METRIC,
    x: str = DEFAULT_X,
    last_n: int = 1,
    group_by: str | None = None,
    columns: Sequence[str] | None = None,
) -> Report:
    """Read, group and summarise the trials under `results_dir` (no files written)."""
    if last_n < 1:
        raise ValueError(f"last_n must be >= 1, got {last_n}")
    notes: list[str] = []
    trials = find_trials(results_dir, notes)
    settings = {(g.env, g.label): g.settings for g in group_trials(trials, group_by)}

    with_metric = [t for t in trials if t.has(metric)]
    if not with_metric:
        keys = sorted({k for t in trials for r in t.rows for k in r})
        close = difflib.get_close_matches(metric, keys, n=5, cutoff=0.4)
        hint = f"; similar keys: {', '.join(close)}" if close else ""
        raise ValueError(
            f"metric {metric!r} is not reported by any of {len(trials)} trial(s){hint}"
        )
    for t in trials:
        if t not in with_metric:
            notes.append(f"{t.path}: no {metric!r}, trial left out")

    if not all(t.has(x) for t in with_metric):
        notes.append(f"x key {x!r} missing in some trials; curves use {FALLBACK_X!r}")
        x = FALLBACK_X

    found = {k for t in with_metric for r in t.rows for k in r if EXTRA_METRIC_RE.search(k)}
    if columns is None:
        columns = headline_columns(found)
    elif list(columns) == ["all"]:
        columns = sorted(found)
    columns = [c for c in columns if c != metric]

    groups: list[GroupStats] = []
    keyed: dict[tuple[str, str], list[Trial]] = {}
    for t in with_metric:
        keyed.setdefault((t.env, t.method), []).append(t)
    for (env, method), members in sorted(keyed.items()):
        finals = [t.final(metric, last_n) for t in members]
        mean, std = mean_std(finals)
        lo, hi = bootstrap_ci(finals)
        steps = float(np.nanmean([t.final(x, 1) for t in members]))
        extra = {c: mean_std([t.final(c, last_n) for t in members]) for c in columns}
        health = group_health(f"{env}: {method}", [t.rows for t in members])
        groups.append(
            GroupStats(
                env, method, len(members), mean, std, lo, hi, iqm(finals), steps, finals, extra,
                settings[(env, method)], health,
            )
        )  # fmt: skip
    return Report(metric, x, last_n, groups, with_metric, list(columns), notes)
