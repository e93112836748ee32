"""A scripted lava-world expert (the best memoryless policy, `best_reactive_policy`) and its
state-only demonstrations, for the imitation-from-observation tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rllib_asor.algorithms.common.demonstrations import (
    Demonstrations,
    rollout_demonstrations,
    save_demonstrations,
)
from rllib_asor.envs.lava import GRID_SIZE, LavaWorldEnv, best_reactive_policy


def lava_expert(obs_mode: str = "onehot"):
    """obs -> action of the best memoryless policy (0.82 under every lava row)."""
    policy = best_reactive_policy()

    def act(obs: np.ndarray) -> int:
        if obs_mode == "onehot":
            row, col = int(np.argmax(obs[:GRID_SIZE])), int(np.argmax(obs[GRID_SIZE:-1]))
        else:
            row, col = int(obs[0]), int(obs[1])
        return int(policy.get((row, col, bool(obs[-1] > 0.5)), 1))

    return act


def lava_demonstrations(
    episodes: int = 20, seed: int = 0, obs_mode: str = "onehot"
) -> Demonstrations:
    """`episodes` expert episodes, the lava row drawn per episode."""
    env = LavaWorldEnv(obs_mode=obs_mode)
    return rollout_demonstrations(lava_expert(obs_mode), env, episodes, seed=seed)


def lava_demonstrations_file(path: Path, episodes: int = 20, seed: int = 0) -> Path:
    save_demonstrations(path, lava_demonstrations(episodes, seed))
    return path
