"""Statistics of finished episodes, as `rllib evaluate` prints them: return mean, std, min and
max, each episode's return, length and ``info["dynamics_id"]``, the returns per dynamics id,
and the means of what the env reports in its last info (`episode_metrics`).

Works on RLlib episodes (`get_return()`, `len()`, `get_infos(-1)`), the ones an env runner
samples, single- and multi-agent.
"""

from __future__ import annotations

import math
from typing import Any

from rllib_asor.evaluation.dynamics import dynamics_id


def summarize(episodes: list[Any]) -> dict[str, Any]:
    """`return_mean`, `return_std`, `return_min`, `return_max`, `returns`, `lengths`,
    `episode_metrics`, `dynamics_ids` (None where the env reports none) and `per_dynamics`
    ({id: {episodes, return_mean}}) of at least one episode."""
    returns = [float(ep.get_return()) for ep in episodes]
    lengths = [int(len(ep)) for ep in episodes]
    ids = [jsonable_id(dynamics_id(ep)) for ep in episodes]
    per_dynamics: dict[str, dict[str, float]] = {}
    for ret, did in zip(returns, ids, strict=True):
        if did is not None:
            row = per_dynamics.setdefault(str(did), {"episodes": 0, "return_sum": 0.0})
            row["episodes"] += 1
            row["return_sum"] += ret
    mean = sum(returns) / len(returns)
    return {
        "return_mean": mean,
        "return_std": math.sqrt(sum((r - mean) ** 2 for r in returns) / len(returns)),
        "return_min": min(returns),
        "return_max": max(returns),
        "returns": returns,
        "lengths": lengths,
        "episode_metrics": episode_metrics(episodes),
        "dynamics_ids": ids,
        "per_dynamics": {
            k: {"episodes": v["episodes"], "return_mean": v["return_sum"] / v["episodes"]}
            for k, v in sorted(per_dynamics.items())
        },
    }


def jsonable_id(value: Any) -> Any:
    """A dynamics id as JSON can hold it (numpy scalars -> Python numbers, else str)."""
    if value is None or isinstance(value, str | int | float):
        return value
    if hasattr(value, "item"):
        return value.item()
    return str(value)


def episode_metrics(episodes: list[Any]) -> dict[str, float]:
    """Means over episodes of what the env reports in its last `info`: the race's
    `info["episode_metrics"]` (success, trapped, unnecessary-jump rate, goal reward, ...) and
    gymnasium's `is_success` (as `success`). Multi-agent episodes count every agent."""
    rows: list[dict[str, float]] = []
    for ep in episodes:
        try:
            info = ep.get_infos(-1)
        except (AttributeError, IndexError, TypeError):
            continue
        infos = (
            info.values() if info and all(isinstance(v, dict) for v in info.values()) else [info]
        )
        for one in infos:
            row = {}
            metrics = one.get("episode_metrics") if isinstance(one, dict) else None
            if isinstance(metrics, dict):
                row.update({k: float(v) for k, v in metrics.items() if _is_number(v)})
            if isinstance(one, dict) and _is_number(one.get("is_success")):
                row.setdefault("success", float(one["is_success"]))
            if row:
                rows.append(row)
    keys = sorted({k for row in rows for k in row})
    return {k: sum(r[k] for r in rows if k in r) / sum(k in r for r in rows) for k in keys}


def _is_number(x: Any) -> bool:
    return isinstance(x, int | float | bool) and math.isfinite(float(x))
