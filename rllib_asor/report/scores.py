"""Which number scores a trial, and the number per ``dynamics_id``.

In order of preference (the first one that every trial of the env has; where none of the
evaluations is in every trial, the evaluation that most trials have, and the trials without it
are left out of the comparison, never scored by another kind of return):

1. ``final-evaluation``: ``evaluation.json`` in the trial folder, written by `rllib ab` /
   `rllib evaluate DIR`: greedy episodes of the final checkpoint, the same env seeds for
   every trial;
2. ``evaluation``: RLlib's evaluation env runners during training
   (``evaluation/env_runners/episode_return_mean``, last value);
3. ``training``: the training (exploring) returns, ``env_runners/episode_return_mean``.

Per dynamics: ``evaluation.json``'s episodes grouped by their ``dynamics_id``, or the
``.../dynamics/<id>/episode_return_mean`` keys that `DynamicsReturnsCallback` logs; with their
episode counts (``evaluation.json``'s ``dynamics_ids``, or ``.../dynamics/<id>/num_episodes``:
the episodes of the iteration(s) scored).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rllib_asor.report.results import Trial

EVAL_FILE = "evaluation.json"
FINAL_KEY = "final_evaluation/episode_return_mean"
"""The metric name of the ``final-evaluation`` score (read from `EVAL_FILE`)."""
TRAIN_KEY = "env_runners/episode_return_mean"
EVAL_KEY = "evaluation/env_runners/episode_return_mean"
DYNAMICS = "dynamics"
RETURN_LEAF = "episode_return_mean"
COUNT_LEAF = "num_episodes"
EVALUATIONS = ("final-evaluation", "evaluation")


@dataclass(frozen=True)
class Source:
    """Where a trial's score comes from."""

    kind: str
    """``final-evaluation``, ``evaluation``, ``training`` or ``metric`` (a key the user named)."""
    key: str
    description: str


def read_evaluation(trial: Trial) -> dict | None:
    """The trial's ``evaluation.json`` (None when absent or unreadable)."""
    path = trial.path / EVAL_FILE
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return None
    return data if isinstance(data, dict) and data.get("returns") else None


def _final_source(ev: dict) -> Source:
    return Source(
        "final-evaluation",
        FINAL_KEY,
        f"final evaluation return: greedy, {len(ev['returns'])} episodes of each final "
        f"checkpoint, env seed {ev.get('seed')} for every trial ({EVAL_FILE})",
    )


EVAL_SOURCE = Source(
    "evaluation",
    EVAL_KEY,
    f"evaluation return during training (greedy, RLlib's evaluation env runners; "
    f"`{EVAL_KEY}`, last value)",
)


def choose_source(trials: Sequence[Trial], metric: str | None = None) -> Source:
    """The best score every trial has, else the evaluation most trials have (see the module
    doc: `has_score` tells which trials it leaves out); `metric` forces a result key."""
    if metric:
        return Source("metric", metric, f"`{metric}` (as asked), mean of the last iteration(s)")
    finals = [ev for ev in (read_evaluation(t) for t in trials) if ev is not None]
    during = sum(t.has(EVAL_KEY) for t in trials)
    if trials and len(finals) == len(trials):
        return _final_source(finals[0])
    if trials and during == len(trials):
        return EVAL_SOURCE
    if finals or during:
        return _final_source(finals[0]) if len(finals) >= during else EVAL_SOURCE
    return Source(
        "training",
        TRAIN_KEY,
        f"training return (exploring; no evaluation recorded; `{TRAIN_KEY}`, last value)",
    )


def has_score(trial: Trial, source: Source) -> bool:
    """Whether `trial` has a score under `source`."""
    if source.kind == "final-evaluation":
        return read_evaluation(trial) is not None
    return trial.has(source.key)


def score(trial: Trial, source: Source, last_n: int = 1) -> float:
    """The trial's score under `source` (NaN when it has none)."""
    if source.kind == "final-evaluation":
        ev = read_evaluation(trial)
        return float(np.mean(ev["returns"])) if ev else math.nan
    return trial.final(source.key, last_n)


def dynamics_scores(trial: Trial, source: Source, last_n: int = 1) -> dict[str, float]:
    """Score per ``dynamics_id`` under `source` ({} when none was recorded)."""
    if source.kind == "final-evaluation":
        ev = read_evaluation(trial) or {}
        ids = ev.get("dynamics_ids") or []
        by: dict[str, list[float]] = {}
        for ret, did in zip(ev.get("returns", []), ids, strict=False):
            if did is not None:
                by.setdefault(str(did), []).append(float(ret))
        return {k: float(np.mean(v)) for k, v in by.items()}
    base = source.key.rsplit("/", 1)[0] + f"/{DYNAMICS}/"
    keys = {
        k for r in trial.rows for k in r if k.startswith(base) and k.endswith("/" + RETURN_LEAF)
    }
    out = {}
    for key in keys:
        value = trial.final(key, last_n)
        if math.isfinite(value):
            out[key[len(base) : -len(RETURN_LEAF) - 1]] = value
    return out


def dynamics_episodes(trial: Trial, source: Source, last_n: int = 1) -> dict[str, int]:
    """Episodes behind each `dynamics_scores` value: the final evaluation's episodes of that
    ``dynamics_id``, or the ``num_episodes`` of the rows scored (the last `last_n` with a
    return); a dynamics whose count was not recorded is left out."""
    if source.kind == "final-evaluation":
        ev = read_evaluation(trial) or {}
        counts: dict[str, int] = {}
        for did in ev.get("dynamics_ids") or []:
            if did is not None:
                counts[str(did)] = counts.get(str(did), 0) + 1
        return counts
    base = source.key.rsplit("/", 1)[0] + f"/{DYNAMICS}/"
    out = {}
    for did in dynamics_scores(trial, source, last_n):
        returns, counts_ = (
            trial.series(f"{base}{did}/{RETURN_LEAF}"),
            trial.series(f"{base}{did}/{COUNT_LEAF}"),
        )
        used = counts_[np.isfinite(returns)][-last_n:]
        if used.size and np.isfinite(used).all():
            out[did] = int(used.sum())
    return out


def seen_dynamics(trial: Trial, key: str) -> set[str]:
    """The ``dynamics_id``s with a return under the result key `key`'s group (e.g.
    `TRAIN_KEY`: the training episodes' dynamics)."""
    base = key.rsplit("/", 1)[0] + f"/{DYNAMICS}/"
    return {
        k[len(base) : -len(RETURN_LEAF) - 1]
        for r in trial.rows
        for k in r
        if k.startswith(base) and k.endswith("/" + RETURN_LEAF)
    }
