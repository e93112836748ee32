"""The race's evaluation: a trained policy on every map, on course seeds training never drew.

Used by `rllib quickstart` (`make train`) and `studies.lib.race_learning`, so the numbers they
print are measured the same way: one racer, `episodes` courses per map with course seeds
`EVAL_SEED0 + episode`, all envs stepped together in one batch; a GIF of one episode.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

COLUMNS = (
    ("success", "success rate"),
    ("trapped", "trapped rate"),
    ("unnecessary_jump_rate", "unnecessary-jump rate"),
    ("distance_from_cliff", "distance from cliff (m)"),
    ("goal_reward", "goal reward"),
    ("total_reward", "total reward"),
)
"""(key of `info["episode_metrics"]`, column title) of the paper's table."""
EVAL_SEED0 = 10_000
"""Course seeds of the evaluation episodes: EVAL_SEED0 + episode index (unseen in training
with probability 1: training draws course seeds 0..999)."""

Policy = Callable[[dict[str, np.ndarray], list[Any]], np.ndarray]
"""`policy(obs_batch, envs) -> actions [N, 8]`: one action per env of the batch."""


def evaluate(
    policy: Policy, episodes: int, max_steps: int, maps: Sequence[int] | None = None
) -> dict[str, Any]:
    """Run `policy` on each map (default: all ten) × `episodes` course seeds.

    Returns the per-map mean of each column (`per_map[map][key]`), the mean over the maps
    (`mean[key]`) and the per-episode metrics (`episodes`: [map, course seed, metrics]).
    """
    import game_env
    from game_env.env import ObstacleRaceEnv

    maps = list(range(game_env.NUM_MAPS)) if maps is None else list(maps)
    pairs = [(m, EVAL_SEED0 + e) for m in maps for e in range(episodes)]
    # The limit goes to the constructor (a TimeLimit wrapper alone is not seen by the env).
    envs = [ObstacleRaceEnv(map_id=m, course_seed=s, max_episode_steps=max_steps) for m, s in pairs]
    obs = [env.reset(seed=s)[0] for env, (_, s) in zip(envs, pairs, strict=True)]
    metrics: list[dict[str, float] | None] = [None] * len(envs)
    try:
        while any(m is None for m in metrics):
            live = [i for i, m in enumerate(metrics) if m is None]
            batch = {k: np.stack([obs[i][k] for i in live]) for k in obs[live[0]]}
            actions = policy(batch, [envs[i] for i in live])
            for i, a in zip(live, actions, strict=True):
                obs[i], _, term, trunc, info = envs[i].step(a)
                if term or trunc:
                    metrics[i] = dict(info["episode_metrics"])
    finally:
        for env in envs:
            env.close()
    per_map: dict[int, dict[str, float]] = {}
    for m in maps:
        rows = [metrics[i] for i, (mm, _) in enumerate(pairs) if mm == m]
        per_map[m] = {k: float(np.mean([r[k] for r in rows])) for k, _ in COLUMNS}
    mean = {k: float(np.mean([per_map[m][k] for m in maps])) for k, _ in COLUMNS}
    return {
        "per_map": per_map,
        "mean": mean,
        "episodes": [[m, s, em] for (m, s), em in zip(pairs, metrics, strict=True)],
    }


def module_policy(module: Any, explore: bool) -> Policy:
    """Batched policy from a trained RLModule (stochastic if `explore`, else its mode)."""
    import torch
    from ray.rllib.core import Columns

    from rllib_asor.devices import module_device

    dist_cls = (
        module.get_exploration_action_dist_cls()
        if explore
        else module.get_inference_action_dist_cls()
    )

    def act(batch: dict[str, np.ndarray], envs: list[Any]) -> np.ndarray:
        device = module_device(module)
        with torch.no_grad():
            obs = {k: torch.as_tensor(v, device=device) for k, v in batch.items()}
            logits = module.forward_inference({Columns.OBS: obs})[Columns.ACTION_DIST_INPUTS]
            dist = dist_cls.from_logits(logits)
            if not explore:
                dist = dist.to_deterministic()
            return dist.sample().cpu().numpy()

    return act


def load_module(checkpoint: str | os.PathLike[str]) -> Any:
    """The policy's RLModule from an algorithm checkpoint written by `rllib train`."""
    from ray.rllib.core import (
        COMPONENT_LEARNER,
        COMPONENT_LEARNER_GROUP,
        COMPONENT_RL_MODULE,
        DEFAULT_MODULE_ID,
    )
    from ray.rllib.core.rl_module.rl_module import RLModule

    path = Path(checkpoint, COMPONENT_LEARNER_GROUP, COMPONENT_LEARNER, COMPONENT_RL_MODULE)
    return RLModule.from_checkpoint(str(path / DEFAULT_MODULE_ID))


def record_gif(
    policy: Policy,
    path: str | os.PathLike[str],
    map_id: int,
    course_seed: int = EVAL_SEED0,
    max_steps: int = 1000,
    every: int = 2,
    size: tuple[int, int] = (320, 240),
) -> dict[str, float]:
    """Write a GIF of one episode (a frame every `every` steps, 12 fps, chase camera) to
    `path` (atomically); return the episode's metrics."""
    import imageio.v2 as imageio

    from game_env.env import ObstacleRaceEnv

    env = ObstacleRaceEnv(
        map_id=map_id,
        course_seed=course_seed,
        max_episode_steps=max_steps,
        render_mode="rgb_array",
        width=size[0],
        height=size[1],
    )
    frames, metrics = [], {}
    try:
        obs, _ = env.reset(seed=course_seed)
        for t in range(max_steps + 1):
            if t % every == 0:
                frames.append(env.render())
            batch = {k: v[None] for k, v in obs.items()}
            obs, _, term, trunc, info = env.step(policy(batch, [env])[0])
            if term or trunc:
                frames.append(env.render())
                metrics = dict(info["episode_metrics"])
                break
    finally:
        env.close()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp.gif")
    imageio.mimsave(tmp, frames, duration=1000 / 12, loop=0)
    tmp.replace(path)
    return metrics
