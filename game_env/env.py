"""Gymnasium env ``game_env/ObstacleRace-v0``: one racer on a procedurally generated course."""

from __future__ import annotations

import warnings
from typing import Any

import gymnasium as gym
import numpy as np

from game_env.base import RaceSimEnvMixin
from game_env.constants import FRAME_SKIP
from game_env.options import (
    check_action,
    check_course_seed,
    check_map_choice,
    check_positive_int,
    check_render_mode,
    first_map,
)
from game_env.sim import RaceSim
from game_env.spaces import action_space, observation_space


class ObstacleRaceEnv(RaceSimEnvMixin, gym.Env):
    """Single-racer obstacle race (see ``game_env.spaces`` for spaces, docs/game_env.md for rules).

    Args:
        map_id: 0..9; a list of map ids (one drawn per reset); or None / "random" to draw
            any of the ten per reset (draws use the env's RNG). `set_map_choice` changes it.
        course_seed: fixed course seed, or None to draw one (0..999) per reset.
        max_episode_steps: env steps before truncation (a Gymnasium ``TimeLimit`` given to
            ``gymnasium.make`` is honoured too).
        frame_skip: MuJoCo steps per env step (timestep 2 ms).
        render_mode: None or "rgb_array"; ``width``/``height`` size the frames.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 25}

    def __init__(
        self,
        map_id: int | list[int] | str | None = 0,
        course_seed: int | None = None,
        max_episode_steps: int = 1000,
        frame_skip: int = FRAME_SKIP,
        render_mode: str | None = None,
        width: int = 320,
        height: int = 240,
    ) -> None:
        self._map_choice = check_map_choice(map_id)
        self._course_seed = check_course_seed(course_seed)
        self.frame_skip = check_positive_int("frame_skip", frame_skip, 1, 1000)
        self._max_steps = check_positive_int("max_episode_steps", max_episode_steps)
        self.render_mode = check_render_mode(render_mode)
        self.width = check_positive_int("width", width, 16, 4096)
        self.height = check_positive_int("height", height, 16, 4096)
        self.observation_space = observation_space()
        self.action_space = action_space()
        self.sim = RaceSim(1, self.frame_skip, self._max_steps)
        self._renderer = None
        self.sim.load(first_map(self._map_choice), 0 if self._course_seed is None else self._course_seed)
        self.sim.reset()
        self._done = False

    @property
    def map_id(self) -> int:
        """The map of the current episode."""
        return self.sim.map_id

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Start an episode; ``options`` may fix ``map_id`` and/or ``course_seed`` for it."""
        super().reset(seed=seed)
        map_id, cseed = self._load_course(self.np_random, options)
        limit = self.spec.max_episode_steps if self.spec is not None and self.spec.max_episode_steps else None
        self.sim.max_episode_steps = limit or self._max_steps
        obs = self.sim.reset()
        self._done = False
        info = {"map_id": map_id, "dynamics_id": map_id, "course_seed": cseed}
        return {k: v[0] for k, v in obs.items()}, info

    def step(self, action: Any) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """One env step; ``info`` carries ``reward_terms``, ``map_id`` (also as ``dynamics_id``: a
        map's elements are its dynamics) and, at the end, the episode metrics."""
        sim = self.sim
        obs, terms, done, err = sim.step([check_action(action)])
        info: dict[str, Any] = {"reward_terms": terms[0],
                                "map_id": sim.map_id, "dynamics_id": sim.map_id,
                                "course_seed": sim.course_seed}
        reward = sum(terms[0].values())
        terminated = bool(done[0])
        truncated = sim.steps >= sim.max_episode_steps
        if err is not None:
            warnings.warn(err, RuntimeWarning, stacklevel=2)
            info["physics_error"] = err
            truncated = True
        # Every step: running values, final on the last step. (An outer TimeLimit from
        # gymnasium.make(max_episode_steps=...) truncates without this env knowing.)
        info["episode_metrics"] = sim.episode_metrics(0)
        return {k: v[0] for k, v in obs.items()}, reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        """An RGB frame (H, W, 3) chasing the racer, when ``render_mode="rgb_array"``."""
        return self._chase_frame(self.sim.pos[0])

    def close(self) -> None:
        """Free the renderer."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
