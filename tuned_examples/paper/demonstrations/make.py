"""Writes the demonstrations the paper's sweep files read, beside this file (`make install` runs it;
the files are not in git: this script writes them bit for bit the same in a few seconds).

    python tuned_examples/paper/demonstrations/make.py

- `lava-expert.npz`: the lava world's best memoryless policy (layout B, one-hot observations,
  greedy return 0.82 under every lava row), 40 episodes, state-only (GAIfO, SOIL in lava.yaml);
- `walker2d-gravity-random.npz`, `halfcheetah-damping-random.npz`: the target transitions of
  GARAT in online.yaml: uniformly random actions on ESCP's 40 training tasks (GARAT's grounding
  MDP plays random actions, docs/baselines.md).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rllib_asor.algorithms.common.demonstrations import (
    rollout_demonstrations,
    save_demonstrations,
)
from rllib_asor.envs.lava import GRID_SIZE, best_reactive_policy

HERE = Path(__file__).parent


def lava_expert():
    table = best_reactive_policy("B")

    def act(obs: np.ndarray) -> int:
        row, col = int(np.argmax(obs[:GRID_SIZE])), int(np.argmax(obs[GRID_SIZE:-1]))
        return table[(row, col, bool(obs[-1] > 0.5))]

    return act


def random_actions(low: float, high: float, dim: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    return lambda obs: rng.uniform(low, high, dim).astype(np.float32)


def main() -> None:
    lava = {"obs_mode": "onehot", "layout": "B"}
    demos = rollout_demonstrations(lava_expert(), "rllib_asor/LavaWorld-v0", 40, env_kwargs=lava)
    save_demonstrations(HERE / "lava-expert.npz", demos)
    walker = {"params": ["gravity"], "num_tasks": 40, "task_seed": 0}
    demos = rollout_demonstrations(
        random_actions(-1, 1, 6), "rllib_asor/Walker2dShift-v0", 100, env_kwargs=walker
    )
    save_demonstrations(HERE / "walker2d-gravity-random.npz", demos)
    cheetah = {"params": ["damping"], "num_tasks": 40, "task_seed": 0, "max_episode_steps": 200}
    demos = rollout_demonstrations(
        random_actions(-1, 1, 6), "rllib_asor/HalfCheetahShift-v0", 15, env_kwargs=cheetah
    )
    save_demonstrations(HERE / "halfcheetah-damping-random.npz", demos)


if __name__ == "__main__":
    main()
