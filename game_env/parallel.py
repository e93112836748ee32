"""PettingZoo ``ParallelEnv``: N racers in one scene (they collide; Attack pushes)."""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
from gymnasium import spaces as gym_spaces
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv

from game_env.constants import FRAME_SKIP
from game_env.env_mixin import RaceSimEnvMixin
from game_env.options import check_action, check_positive_int
from game_env.scene import MAX_RACERS
from game_env.spaces import action_space, observation_space

_IDLE = (1, 1, 0, 0, 0, 0, 0, 1)  # what a racer without an action this step does


class RaceParallelEnv(RaceSimEnvMixin, ParallelEnv):
    """N racers ("racer_0", ...) race the same course; a finished racer leaves ``agents``.

    Arguments as ``ObstacleRaceEnv`` plus ``num_racers`` (1..16); ``episode_metrics`` come in
    each racer's last info only, and ``step_info="lean"`` leaves out ``reward_terms``.
    """

    metadata = {"name": "obstacle_race_v0", "render_modes": ["rgb_array"], "render_fps": 25,
                "is_parallelizable": True}

    def __init__(
        self,
        num_racers: int = 4,
        map_id: int | list[int] | str | None = 0,
        course_seed: int | None = None,
        max_episode_steps: int = 1000,
        frame_skip: int = FRAME_SKIP,
        render_mode: str | None = None,
        width: int = 320,
        height: int = 240,
        step_info: str = "full",
    ) -> None:
        self.num_racers = check_positive_int("num_racers", num_racers, 1, MAX_RACERS)
        self.max_episode_steps = self._setup(self.num_racers, map_id, course_seed, max_episode_steps, frame_skip,
                                             render_mode, width, height, step_info)
        self.possible_agents = [f"racer_{i}" for i in range(self.num_racers)]
        self.agents: list[str] = []
        self._rng, _ = seeding.np_random(None)
        self._index = {a: i for i, a in enumerate(self.possible_agents)}
        self._live: set[str] = set()

    @functools.cache  # noqa: B019 - PettingZoo wants the same object per agent
    def observation_space(self, agent: str) -> gym_spaces.Dict:
        """The (same, cached) observation space of every racer."""
        return observation_space()

    @functools.cache  # noqa: B019
    def action_space(self, agent: str) -> gym_spaces.MultiDiscrete:
        """The (same, cached) action space of every racer."""
        return action_space()

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, dict[str, np.ndarray]], dict[str, dict[str, Any]]]:
        """Start an episode: every racer on the start pad (``options`` as the Gymnasium env)."""
        if seed is not None:
            self._rng, _ = seeding.np_random(seed)
        self._load_course(self._rng, options)
        obs = self.sim.reset()
        self.agents = list(self.possible_agents)
        self._live = set(self.agents)
        info = self._course_info()
        return self._split(obs, self.agents), {a: dict(info) for a in self.agents}

    def _split(self, obs: dict[str, np.ndarray], agents: list[str]) -> dict[str, dict[str, np.ndarray]]:
        keys = list(obs)
        per_racer = list(zip(*(list(v) for v in obs.values()), strict=True))  # N tuples of views
        index = self._index
        return {a: dict(zip(keys, per_racer[index[a]], strict=True)) for a in agents}

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """One env step for every live racer; missing racers stand idle."""
        acts = [list(_IDLE) for _ in range(self.num_racers)]
        index, live_set = self._index, self._live
        for agent, action in actions.items():
            i = index.get(agent)
            if i is None:
                raise ValueError(f"agent {agent!r} is unknown; allowed: {self.possible_agents}")
            if agent in live_set:
                acts[i] = check_action(action)
        sim = self.sim
        obs, terms, done, err = sim.step(acts)
        live = self.agents
        truncate = sim.steps >= self.max_episode_steps or err is not None
        self._warn_physics(err)
        rewards, terminations, truncations, infos = {}, {}, {}, {}
        index = self._index
        for a in live:
            i = index[a]
            info = self._step_info(terms[i], err)
            rewards[a] = sum(terms[i].values())
            terminations[a] = bool(done[i])
            truncations[a] = bool(truncate)
            if terminations[a] or truncations[a]:
                info["episode_metrics"] = sim.episode_metrics(i)
            infos[a] = info
        observations = self._split(obs, live)
        self.agents = [a for a in live if not (terminations[a] or truncations[a])]
        self._live = set(self.agents)
        return observations, rewards, terminations, truncations, infos

    def render(self) -> np.ndarray | None:
        """An RGB frame chasing the leading racer, when ``render_mode="rgb_array"``."""
        pos = self.sim.pos
        return self._chase_frame(pos[int(np.argmax(pos[:, 0]))])


def parallel_env(num_racers: int = 4, map_id: int | list[int] | str | None = 0, **kwargs: Any) -> RaceParallelEnv:
    """A PettingZoo ParallelEnv with ``num_racers`` racers on map ``map_id``."""
    return RaceParallelEnv(num_racers=num_racers, map_id=map_id, **kwargs)
