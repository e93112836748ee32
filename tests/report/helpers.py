"""Tune-like trial folders written by hand (result.json rows nested as RLlib's new stack
reports them, params.json, optionally evaluation.json), with known scores."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any


def write_trial(
    root: Path,
    name: str,
    params: dict[str, Any],
    returns: list[float],
    *,
    eval_returns: list[float] | None = None,
    eval_dynamics: dict[str, list[float]] | None = None,
    evaluation: dict[str, Any] | None = None,
    steps_per_iter: int = 1000,
    extra: dict[str, Any] | None = None,
) -> Path:
    """One trial folder `root/name` with one result row per entry of `returns`.

    `eval_returns` / `eval_dynamics` (dynamics id -> value per iteration) add the
    `evaluation/env_runners/...` keys; `evaluation` is written as evaluation.json; `extra`
    adds keys to every row (``a/b`` names nested keys as RLlib reports them).
    """
    tdir = root / name
    tdir.mkdir(parents=True)
    (tdir / "params.json").write_text(json.dumps(params))
    with (tdir / "result.json").open("w") as f:
        for i, ret in enumerate(returns):
            row: dict[str, Any] = {
                "env_runners": {"episode_return_mean": ret},
                "num_env_steps_sampled_lifetime": (i + 1) * steps_per_iter,
                "training_iteration": i + 1,
                "config": params,
            }
            if eval_returns is not None:
                runners: dict[str, Any] = {"episode_return_mean": eval_returns[i]}
                if eval_dynamics:
                    runners["dynamics"] = {
                        d: {"episode_return_mean": v[i]} for d, v in eval_dynamics.items()
                    }
                row["evaluation"] = {"env_runners": runners}
            row.update(extra or {})
            f.write(json.dumps(row) + "\n")
    if evaluation is not None:
        (tdir / "evaluation.json").write_text(json.dumps(evaluation))
    return tdir
