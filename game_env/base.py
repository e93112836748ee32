"""What the Gymnasium and the PettingZoo env share: MuJoCo handles and the course per reset."""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from game_env.maps import NUM_MAPS
from game_env.options import COURSE_SEEDS, MapChoice, check_map_choice, check_reset_options
from game_env.sim import RaceSim


class RaceSimEnvMixin:
    """Mixed into both envs; they set `sim`, `frame_skip`, `_map_choice`, `_course_seed`,
    `_renderer`, `render_mode`, `width` and `height` in their constructors."""

    sim: RaceSim
    frame_skip: int
    _map_choice: MapChoice
    _course_seed: int | None
    _renderer: Any
    render_mode: str | None
    width: int
    height: int

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
        (`rllib_asor.rllib.curriculum`) call this on every env."""
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
