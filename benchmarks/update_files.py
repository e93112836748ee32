"""Which of the package's files one ASOR Learner update runs, and how deep its Learner stacks.

Builds the PPO+ASOR and ESCP+ASOR Learners in this process (small networks, no Ray), runs one
update to warm up, then a second under `sys.setprofile` and lists every `rllib_asor/` file
whose code ran (building the Learner not counted), grouped by folder, with the Learner's class
stack (its MRO up to RLlib's `Learner`) and the classes in it that define `_update`; the same
for the algorithm without ASOR gives the files ASOR adds to its update.

    OMP_NUM_THREADS=1 python -m benchmarks.update_files          # both
    python -m benchmarks.update_files --algos escp --json out.json

docs/architecture.md quotes its output.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from ray.rllib.core import DEFAULT_MODULE_ID, Columns
from ray.rllib.core.learner.learner import Learner
from ray.rllib.env.single_agent_episode import SingleAgentEpisode
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

import rllib_asor

PACKAGE = Path(rllib_asor.__file__).resolve().parent
OBS = gym.spaces.Box(-10, 10, (3,), np.float32)
SMALL = {"disc_hiddens": [16], "rnd_hiddens": [16], "rnd_embedding_dim": 8, "seed": 0}


def ppo_update(asor: bool = True) -> tuple[Learner, Callable[[], Any]]:
    """PPO(+ASOR)'s Learner and one update on six short episodes."""
    from ray.rllib.algorithms.ppo import PPOConfig

    act = gym.spaces.Discrete(2)
    config = (
        PPOConfig()
        .environment(observation_space=OBS, action_space=act)
        .training(train_batch_size=60, minibatch_size=30, num_epochs=2)
        .rl_module(model_config={"fcnet_hiddens": [16]})
        .debugging(seed=0)
    )
    config = rllib_asor.with_asor(config, **SMALL) if asor else config
    learner = config.build_learner(env=None, spaces={"__env__": (OBS, act), DEFAULT_MODULE_ID: (OBS, act)})
    rng = np.random.default_rng(0)
    episodes = []
    for i in range(6):
        ep = SingleAgentEpisode(observation_space=OBS, action_space=act)
        ep.add_env_reset(observation=rng.normal(size=3).astype(np.float32))
        for t in range(10):
            ep.add_env_step(
                observation=rng.normal(size=3).astype(np.float32),
                action=int(rng.integers(2)),
                reward=float(i % 2) if t == 9 else -0.02,
                terminated=t == 9,
                extra_model_outputs={
                    Columns.ACTION_LOGP: np.float32(-0.69),
                    Columns.ACTION_DIST_INPUTS: np.zeros(2, np.float32),
                },
            )
        episodes.append(ep.to_numpy())

    def update() -> Any:
        return learner.update(
            episodes=episodes,
            timesteps={NUM_ENV_STEPS_SAMPLED_LIFETIME: 60},
            minibatch_size=30,
            num_epochs=2,
        )

    return learner, update


def escp_update(asor: bool = True) -> tuple[Learner, Callable[[], Any]]:
    """ESCP(+ASOR)'s Learner and one Learner call on 64 replayed rows with their windows."""
    from rllib_asor.algorithms.escp.replay import DYNAMICS_ID, NEXT_WINDOW, WINDOW
    from rllib_asor.algorithms.sac.replay import FlatTransitions

    act = gym.spaces.Box(-1, 1, (2,), np.float32)
    config = (
        rllib_asor.EscpConfig()
        .environment(observation_space=OBS, action_space=act)
        .training(
            train_batch_size_per_learner=32,
            replay_buffer_config={"type": "EpisodeReplayBuffer", "capacity": 1000},
        )
        .escp(history_len=4, rmdm_min_replay=0)
        .debugging(seed=0)
    )
    config = rllib_asor.with_asor(config, **SMALL) if asor else config
    learner = config.build_learner(env=None, spaces={"__env__": (OBS, act), DEFAULT_MODULE_ID: (OBS, act)})
    n, rng = 64, np.random.default_rng(0)
    obs = rng.normal(size=(n, 3)).astype(np.float32)
    cols = {
        Columns.OBS: obs,
        Columns.NEXT_OBS: obs + np.float32(0.1),
        Columns.ACTIONS: rng.uniform(-1, 1, (n, 2)).astype(np.float32),
        Columns.REWARDS: (np.arange(n) % 2).astype(np.float32),
        Columns.TERMINATEDS: np.zeros(n, bool),
        Columns.TRUNCATEDS: np.zeros(n, bool),
        WINDOW: rng.normal(size=(n, 4, 5)).astype(np.float32),
        NEXT_WINDOW: rng.normal(size=(n, 4, 5)).astype(np.float32),
        DYNAMICS_ID: (np.arange(n) % 3).astype(np.int64),
    }

    replayed = [FlatTransitions(cols)]  # what ESCP's replay buffer hands the Learner

    def update() -> Any:
        return learner.update(episodes=replayed, timesteps={NUM_ENV_STEPS_SAMPLED_LIFETIME: 1000})

    return learner, update


BUILDERS = {"ppo": ppo_update, "escp": escp_update}


def files_run(update: Callable[[], Any]) -> list[str]:
    """The package's files (relative paths) whose code ran during `update()`."""
    seen: set[str] = set()

    def profile(frame: Any, event: str, arg: Any) -> None:
        if event == "call":
            seen.add(frame.f_code.co_filename)

    sys.setprofile(profile)
    try:
        update()
    finally:
        sys.setprofile(None)
    root = PACKAGE.parent
    return sorted(
        str(Path(f).resolve().relative_to(root))
        for f in seen
        if Path(f).resolve().is_relative_to(PACKAGE)
    )


def class_stack(learner: Learner) -> dict[str, list[str]]:
    """The Learner's classes above RLlib's `Learner` and those among them defining `_update`."""
    mro = type(learner).__mro__
    stack = list(mro[: mro.index(Learner)])
    return {
        "classes": [c.__qualname__ for c in stack],
        "define_update": [c.__qualname__ for c in stack if "_update" in vars(c)],
    }


def measure(algo: str) -> dict[str, Any]:
    """The files and Learner classes of one update with ASOR, and the files ASOR adds to the
    same update without it."""
    runs = {}
    for asor in (False, True):
        learner, update = BUILDERS[algo](asor)
        update()  # warm-up: lazily built pieces are not the update's files
        runs[asor] = files_run(update), learner
    files, learner = runs[True]
    folders: dict[str, list[str]] = defaultdict(list)
    for f in files:
        folder, name = f.rsplit("/", 1)
        folders[folder].append(name)
    added = sorted(set(files) - set(runs[False][0]))
    return {
        "files": len(files),
        "folders": dict(folders),
        "asor_adds": len(added),
        "added_files": added,
        **class_stack(learner),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--algos", default="ppo,escp", help="comma list of: ppo, escp")
    parser.add_argument("--json", type=Path, help="also write the result here")
    args = parser.parse_args(argv)
    out = {}
    for algo in args.algos.split(","):
        if algo not in BUILDERS:
            parser.error(f"--algos: unknown {algo!r}; allowed: {', '.join(BUILDERS)}")
        out[algo] = res = measure(algo)
        print(
            f"{algo.upper()}+ASOR update: {res['files']} files in {len(res['folders'])} folders, "
            f"{res['asor_adds']} of them not run by {algo.upper()} without ASOR"
        )
        for folder, names in res["folders"].items():
            print(f"  {folder}/: {', '.join(names)}")
        print(f"  Learner: {len(res['classes'])} classes; `_update` in {len(res['define_update'])}: "
              f"{', '.join(res['define_update'])}")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
