"""What the lava world's imitation-from-observation checks (studies/bco_soil_check,
studies/ifo_online_check) share: a policy's mean return over the lava rows, and their
results.json, updated one key at a time (each finished run saved at once)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import rllib_asor  # noqa: F401  (registers our env ids)
from studies.lib.common import write_json

LAVA = {"obs_mode": "onehot", "layout": "B"}
"""The checks' lava world: layout B, one-hot observations."""


def lava_score(act: Callable[[np.ndarray], int], episodes_per_row: int = 1, seed: int = 0) -> float:
    """Mean return of `act` (obs → action) over `episodes_per_row` episodes per lava row 2-5."""
    env = gym.make("rllib_asor/LavaWorld-v0", **LAVA)
    total, n = 0.0, 0
    for k in (2, 3, 4, 5):
        for i in range(episodes_per_row):
            obs, _ = env.reset(seed=seed + i, options={"lava_row": k})
            done, ret = False, 0.0
            while not done:
                obs, r, term, trunc, _ = env.step(act(obs))
                ret, done = ret + r, term or trunc
            total, n = total + ret, n + 1
    return total / n


def save_result(path: Path, key: str, value: Any) -> None:
    """Set `key` in the JSON object at `path` (made if missing), written atomically."""
    data = json.loads(path.read_text()) if path.exists() else {}
    data[key] = value
    write_json(path, data)
