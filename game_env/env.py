"""Gymnasium env ``game_env/ObstacleRace-v0``: one racer on a procedurally generated course."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from game_env.constants import FRAME_SKIP
from game_env.env_mixin import RaceSimEnvMixin
from game_env.options import check_action
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
        step_info: "full" (default): every step's info has ``reward_terms`` and the running
            ``episode_metrics``; "lean": neither, except ``episode_metrics`` on the step this
            env ends the episode (its own ``max_episode_steps``; a ``TimeLimit`` given to
            ``gymnasium.make`` ends it unseen). The race's RLlib configs use "lean".
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
        step_info: str = "full",
    ) -> None:
        self._max_steps = self._setup(1, map_id, course_seed, max_episode_steps, frame_skip, render_mode,
                                      width, height, step_info)
        self.observation_space = observation_space()
        self.action_space = action_space()

    @property
    def map_id(self) -> int:
        """The map of the current episode."""
        return self.sim.map_id

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Start an episode; ``options`` may fix ``map_id`` and/or ``course_seed`` for it."""
        super().reset(seed=seed)
        self._load_course(self.np_random, options)
        limit = self.spec.max_episode_steps if self.spec is not None and self.spec.max_episode_steps else None
        self.sim.max_episode_steps = limit or self._max_steps
        obs = self.sim.reset()
        return {k: v[0] for k, v in obs.items()}, self._course_info()

    def step(self, action: Any) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """One env step; ``info`` carries ``reward_terms``, ``map_id`` (also as ``dynamics_id``: a
        map's elements are its dynamics) and, at the end, the episode metrics."""
        sim = self.sim
        obs, terms, done, err = sim.step([check_action(action)])
        info = self._step_info(terms[0], err)
        reward = sum(terms[0].values())
        terminated = bool(done[0])
        truncated = sim.steps >= sim.max_episode_steps or err is not None
        self._warn_physics(err)
        # "full": every step running values, final on the last step (an outer TimeLimit from
        # gymnasium.make(max_episode_steps=...) truncates without this env knowing).
        if self.step_info == "full" or terminated or truncated:
            info["episode_metrics"] = sim.episode_metrics(0)
        return {k: v[0] for k, v in obs.items()}, reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        """An RGB frame (H, W, 3) chasing the racer, when ``render_mode="rgb_array"``."""
        return self._chase_frame(self.sim.pos[0])
