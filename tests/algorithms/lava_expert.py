"""State-only demonstrations of the scripted lava-world expert (`reactive_expert`: the best
memoryless policy), for the imitation-from-observation tests."""

from __future__ import annotations

from pathlib import Path

from rllib_asor.algorithms.common.demonstrations import (
    Demonstrations,
    rollout_demonstrations,
    save_demonstrations,
)
from rllib_asor.envs.lava import LavaWorldEnv, reactive_expert


def lava_demonstrations(
    episodes: int = 20, seed: int = 0, obs_mode: str = "onehot"
) -> Demonstrations:
    """`episodes` expert episodes, the lava row drawn per episode."""
    env = LavaWorldEnv(obs_mode=obs_mode)
    return rollout_demonstrations(reactive_expert(obs_mode=obs_mode), env, episodes, seed=seed)


def lava_demonstrations_file(path: Path, episodes: int = 20, seed: int = 0) -> Path:
    save_demonstrations(path, lava_demonstrations(episodes, seed))
    return path
