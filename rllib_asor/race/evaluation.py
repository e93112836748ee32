"""The race's evaluation: a trained policy on every map, on course seeds training never drew.

Used by `rllib quickstart` (`make train`) and `studies.lib.race_learning`, so the numbers they
print are measured the same way (policies: `rllib_asor.evaluation.rollout.module_policy`): one racer, `episodes` courses per map with course seeds
`EVAL_SEED0 + episode`, all envs stepped together in one batch; a GIF of one episode. The
episodes run through the project's one loop (`rllib_asor.evaluation.rollout.play`); what is the
race's here is which envs, the paper's columns and the frames.
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
"""`policy(obs_batch, infos) -> actions [N, 8]`: one action per env of the stacked batch
(`rllib_asor.evaluation.rollout.module_policy`)."""


def evaluate(
    policy: Policy | Callable[[list[Any]], Policy],
    episodes: int,
    max_steps: int,
    maps: Sequence[int] | None = None,
    *,
    needs_envs: bool = False,
) -> dict[str, Any]:
    """Run `policy` on each map (default: all ten) × `episodes` course seeds; with
    `needs_envs`, `policy(envs)` makes the policy from the evaluation's envs (a policy that
    reads the simulator, such as `game_env.scripted.ScriptedRacer`).

    Returns the per-map mean of each column (`per_map[map][key]`), the mean over the maps
    (`mean[key]`) and the per-episode metrics (`episodes`: [map, course seed, metrics]).
    """
    import game_env
    from game_env.env import ObstacleRaceEnv
    from rllib_asor.evaluation.rollout import play, stack_obs

    maps = list(range(game_env.NUM_MAPS)) if maps is None else list(maps)
    pairs = [(m, EVAL_SEED0 + e) for m in maps for e in range(episodes)]
    # The limit goes to the constructor (a TimeLimit wrapper alone is not seen by the env).
    envs = [ObstacleRaceEnv(map_id=m, course_seed=s, max_episode_steps=max_steps) for m, s in pairs]
    act = policy(envs) if needs_envs else policy
    try:
        done = play(envs, [s for _, s in pairs], lambda obs, infos: act(stack_obs(obs), infos))
    finally:
        for env in envs:
            env.close()
    metrics = [dict(ep.info["episode_metrics"]) for ep in done]
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
    from rllib_asor.evaluation.rollout import play, stack_obs

    env = ObstacleRaceEnv(
        map_id=map_id,
        course_seed=course_seed,
        max_episode_steps=max_steps,
        render_mode="rgb_array",
        width=size[0],
        height=size[1],
    )
    frames: list[Any] = []
    steps = iter(range(max_steps + 1))

    def act(obs: list[Any], infos: list[Any]) -> np.ndarray:  # a frame every `every` steps
        if next(steps) % every == 0:
            frames.append(env.render())
        return policy(stack_obs(obs), infos)

    try:
        (ep,) = play([env], [course_seed], act)
        frames.append(env.render())  # the last state
    finally:
        env.close()
    metrics = dict(ep.info.get("episode_metrics", {}))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp.gif")
    imageio.mimsave(tmp, frames, duration=1000 / 12, loop=0)
    tmp.replace(path)
    return metrics
