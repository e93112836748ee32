"""Which number scores a trial, and the number per ``dynamics_id``.

In order of preference (the first one that every trial of the env has):

1. ``final-evaluation``: ``evaluation.json`` in the trial folder, written by `rllib ab` /
   `rllib evaluate DIR`: greedy episodes of the final checkpoint, the same env seeds for
   every trial;
2. ``evaluation``: RLlib's evaluation env runners during training
   (``evaluation/env_runners/episode_return_mean``, last value);
3. ``training``: the training (exploring) returns, ``env_runners/episode_return_mean``.

Per dynamics: ``evaluation.json``'s episodes grouped by their ``dynamics_id``, or the
``.../dynamics/<id>/episode_return_mean`` keys that `DynamicsReturnsCallback` logs.
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


def choose_source(trials: Sequence[Trial], metric: str | None = None) -> Source:
    """The best score every trial has (see the module doc); `metric` forces a result key."""
    if metric:
        return Source("metric", metric, f"`{metric}` (as asked), mean of the last iteration(s)")
    if trials and all(read_evaluation(t) is not None for t in trials):
        ev = read_evaluation(trials[0]) or {}
        return Source(
            "final-evaluation",
            FINAL_KEY,
            f"final evaluation return: greedy, {len(ev['returns'])} episodes of each final "
            f"checkpoint, env seed {ev.get('seed')} for every trial ({EVAL_FILE})",
        )
    if trials and all(t.has(EVAL_KEY) for t in trials):
        return Source(
            "evaluation",
            EVAL_KEY,
            f"evaluation return during training (greedy, RLlib's evaluation env runners; "
            f"`{EVAL_KEY}`, last value)",
        )
    return Source(
        "training",
        TRAIN_KEY,
        f"training return (exploring; no evaluation recorded; `{TRAIN_KEY}`, last value)",
    )


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
