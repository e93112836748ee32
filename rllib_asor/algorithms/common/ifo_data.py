"""Offline data for the imitation-from-observation baselines (BCO, SOIL): the dataset parts of a
config's `input_`, their transitions (s, a, s′) for the inverse dynamics model, and the policy's
own evaluation under the data's dynamics (MAPLE's `evaluation/...` keys, which
`rllib compare --table` reads for methods that evaluate themselves)."""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from rllib_asor.algorithms.common.demonstrations import resolve_path


def offline_parts(config: Any) -> list[str]:
    """The dataset part dirs of a config's `input_` (empty online)."""
    paths = getattr(config, "input_", None)
    if not paths or paths == "sampler":
        return []
    return [os.fspath(p) for p in ([paths] if isinstance(paths, str | os.PathLike) else paths)]


def dataset_transitions(parts: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(s, a, s′) of every episode of `rllib data collect` parts (with their own actions)."""
    from rllib_asor.algorithms.maple.data import read_part

    obs, act, nxt = [], [], []
    for part in parts:
        path = resolve_path(part)
        if not Path(path).is_dir():
            raise ValueError(
                f"offline input {part} does not exist; allowed: dataset part dirs written by "
                "`rllib data collect` (e.g. data/offline/hopper/original/medium)"
            )
        for o, a, _, _ in read_part(path):
            obs.append(o[:-1])
            act.append(a)
            nxt.append(o[1:])
    if not obs:
        raise ValueError(f"no transitions in {', '.join(parts)}; allowed: non-empty dataset parts")
    return np.concatenate(obs), np.concatenate(act), np.concatenate(nxt)


def evaluate_on_data(algo: Any, episodes: int = 5) -> dict[str, float]:
    """The greedy policy's return (and D4RL score, where the data has reference returns) under
    each dynamics of an offline config's data, flat (`<dynamics>/return_mean`, `mean/...`, as
    MAPLE logs under `evaluation/`); empty when the parts are not in a `rllib data collect`
    task dir."""
    from rllib_asor.data.format import MANIFEST, read_manifest
    from rllib_asor.data.scoring import score_dynamics
    from rllib_asor.evaluation.rollout import module_actor, policy_module

    parts = offline_parts(algo.config)
    root = Path(resolve_path(parts[0])).parent.parent if parts else None
    if root is None or not (root / MANIFEST).is_file():
        return {}
    t0 = time.perf_counter()
    res = score_dynamics(
        module_actor(policy_module(algo)), read_manifest(root), episodes=episodes, seed=10_000,
        unscored_ok=True,
    )  # fmt: skip
    flat = {f"{d}/{k}": v for d, stats in res.items() for k, v in stats.items() if np.isfinite(v)}
    flat["seconds"] = time.perf_counter() - t0
    return flat
