"""What the Gymnasium and the PettingZoo env share: argument checks, the simulator and its
MuJoCo handles, the course per reset, the info dict, rendering and ``close``."""

from __future__ import annotations

import warnings
from typing import Any

import mujoco
import numpy as np

from game_env.maps import NUM_MAPS
from game_env.options import (
    COURSE_SEEDS,
    MapChoice,
    check_course_seed,
    check_map_choice,
    check_positive_int,
    check_render_mode,
    check_reset_options,
    check_step_info,
    first_map,
)
from game_env.sim import RaceSim


class RaceSimEnvMixin:
    """Mixed into both envs (before the Gymnasium/PettingZoo base class); their constructors
    call `_setup`, which sets the attributes below."""

    sim: RaceSim
    frame_skip: int
    _map_choice: MapChoice
    _course_seed: int | None
    _renderer: Any
    render_mode: str | None
    width: int
    height: int
    step_info: str

    def _setup(self, num_racers: int, map_id: Any, course_seed: Any, max_episode_steps: Any, frame_skip: Any,
               render_mode: Any, width: Any, height: Any, step_info: Any = "full") -> int:
        """Check the constructor arguments both envs take (a ``ValueError`` names a bad one) and
        build the simulator on the first course; returns the checked ``max_episode_steps``."""
        self._map_choice = check_map_choice(map_id)
        self._course_seed = check_course_seed(course_seed)
        self.frame_skip = check_positive_int("frame_skip", frame_skip, 1, 1000)
        max_steps = check_positive_int("max_episode_steps", max_episode_steps)
        self.render_mode = check_render_mode(render_mode)
        self.width = check_positive_int("width", width, 16, 4096)
        self.height = check_positive_int("height", height, 16, 4096)
        self.step_info = check_step_info(step_info)
        self.sim = RaceSim(num_racers, self.frame_skip, max_steps)
        self._renderer = None
        self.sim.load(first_map(self._map_choice), 0 if self._course_seed is None else self._course_seed)
        self.sim.reset()  # model and data exist before the first reset
        return max_steps

    @property
    def model(self) -> mujoco.MjModel:
        """The MuJoCo model of the current course."""
        return self.sim.model

    @property
    def data(self) -> mujoco.MjData:
        """The MuJoCo data of the current episode."""
        return self.sim.data

    @property
    def dt(self) -> float:
        """Seconds of race time per env step (timestep x frame_skip)."""
        return self.sim.model.opt.timestep * self.frame_skip

    @property
    def map_choice(self) -> MapChoice:
        """Maps the next resets draw from: an int, a tuple of ints, or None (all ten)."""
        return self._map_choice

    def set_map_choice(self, map_id: Any) -> None:
        """Change the maps drawn from at the next reset (as the ``map_id`` argument: an int,
        a list of ints, or None/"random"); the running episode is not touched. Curricula
        (`rllib_asor.race.curriculum`) call this on every env."""
        self._map_choice = check_map_choice(map_id)

    def _chase_frame(self, racer_pos: np.ndarray) -> np.ndarray | None:
        """An RGB frame chasing `racer_pos` when ``render_mode="rgb_array"``, else None."""
        if self.render_mode != "rgb_array":
            return None
        if self._renderer is None:
            from game_env.render import RaceRenderer

            self._renderer = RaceRenderer(self.sim.model, self.width, self.height)
        self.sim.sync_visuals()
        return self._renderer.chase(self.sim.data, racer_pos)

    def _load_course(self, rng: np.random.Generator, options: dict[str, Any] | None) -> tuple[int, int]:
        """Pick (map_id, course_seed) for this episode (options, fixed choice, or `rng`) and
        load it; a renderer bound to a replaced model is dropped."""
        opts = check_reset_options(options)
        map_id = opts.get("map_id", self._map_choice)
        if map_id is None:
            map_id = int(rng.integers(NUM_MAPS))
        elif isinstance(map_id, tuple):
            map_id = map_id[int(rng.integers(len(map_id)))]
        cseed = opts.get("course_seed", self._course_seed)
        if cseed is None:
            cseed = int(rng.integers(COURSE_SEEDS))
        old = getattr(self.sim, "model", None)
        self.sim.load(map_id, cseed)
        if self._renderer is not None and self.sim.model is not old:
            self._renderer.close()
            self._renderer = None
        return map_id, cseed

    def _course_info(self) -> dict[str, Any]:
        """The info every reset and step carries: ``map_id`` (also as ``dynamics_id``: a map's
        elements are its dynamics) and ``course_seed`` of the current episode."""
        sim = self.sim
        return {"map_id": sim.map_id, "dynamics_id": sim.map_id, "course_seed": sim.course_seed}

    def _step_info(self, terms: dict[str, float], err: str | None) -> dict[str, Any]:
        """One racer's step info: its ``reward_terms`` (not with ``step_info="lean"``), the
        course info and, after a physics blow-up, ``physics_error`` (the caller truncates)."""
        course = self._course_info()
        info = {"reward_terms": terms, **course} if self.step_info == "full" else course
        if err is not None:
            info["physics_error"] = err
        return info

    @staticmethod
    def _warn_physics(err: str | None) -> None:
        """Warn (at the caller of ``step``) when the physics blew up this step."""
        if err is not None:
            warnings.warn(err, RuntimeWarning, stacklevel=3)

    def close(self) -> None:
        """Free the renderer."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
