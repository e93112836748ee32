"""Shared helpers of the game_env tests: find courses with an element, place a racer."""

from __future__ import annotations

import numpy as np

from game_env.constants import FEET
from game_env.generator import generate_course
from game_env.sim import RaceSim

IDLE = np.array([[1, 1, 0, 0, 0, 0, 0, 1]])


def course_with(map_id: int, attr: str, pick=None, seeds: range = range(40)):
    """First (seed, element) of map ``map_id`` whose course has ``attr`` elements."""
    for seed in seeds:
        course = generate_course(map_id, seed)
        for element in getattr(course, attr):
            if pick is None or pick(element):
                return seed, element
    raise AssertionError(f"no course of map {map_id} has {attr}")


def sim_at(map_id: int, seed: int, x: float, y: float, feet_z: float) -> RaceSim:
    """A one-racer sim reset on (map_id, seed) with its racer moved to (x, y, feet_z)."""
    sim = RaceSim(1)
    sim.load(map_id, seed)
    sim.reset()
    place(sim, x, y, feet_z)
    return sim


def place(sim: RaceSim, x: float, y: float, feet_z: float) -> None:
    sim.data.qpos[sim.qpos_i[0]] = [x, y, feet_z + FEET]
    sim.data.qvel[sim.qvel_i[0]] = 0.0
    sim.racers[0].anchor = (x, y)
    sim.last_pos = sim.data.qpos[sim.qpos_flat].tolist()
