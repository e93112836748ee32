"""Observation/action spaces, reward-term and metric names of the obstacle race.

This module is the contract with the learning side (the RLlib race network): keep the
names, shapes and orders below stable.

Observation (``gymnasium.spaces.Dict``, every Box ``float32``, channels first):

* ``terrain`` (4, 16, 16): [height, type] at cell size 1.0 m, then [height, type] at 2.0 m.
  Height is relative to the racer's feet, divided by 5 m and clipped to [-1, 1]; void (no
  floor) reads -1. Type is a terrain code / 8 in [0, 1] (see ``TERRAIN_TYPES``).
* ``items`` (2, 16, 16): item code / 6 in [0, 1] at 1.0 m and 2.0 m (see ``ITEM_TYPES``).
* ``targets`` (3, 16, 16): archive points at 1.0, 4.0, 16.0 m; 1 = not yet reached,
  0.5 = reached, 0 = none.
* ``goals`` (3, 16, 16): intermediate goals and the destination at 1.0, 4.0, 16.0 m; same
  coding as ``targets``.
* ``agent`` (32,): see ``AGENT_FEATURES`` (index = position in the vector), all in [-1, 1].
* ``destination`` (9,): see ``DESTINATION_FEATURES``, all in [-1, 1].

Grids are world-aligned (axis 1 = world x, axis 2 = world y), centred on the racer: cell
(8, 8) holds the racer. The course runs along +x.

Action ``MultiDiscrete([3, 3, 2, 2, 2, 2, 8, 2])`` = ``ACTION_NAMES``: MoveX {0:-, 1:0, 2:+},
MoveY {0:-, 1:0, 2:+} (world axes), Jump, Sprint, Attack (pushes a racer in front), UseProp
(dash if a prop is held), UsePropDir (dash direction, k*45 degrees from +x), Idle (stand still).
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

GRID = 16
TERRAIN_CELLS = (1.0, 2.0)
ITEM_CELLS = (1.0, 2.0)
TARGET_CELLS = (1.0, 4.0, 16.0)
GOAL_CELLS = (1.0, 4.0, 16.0)

OBS_SHAPES: dict[str, tuple[int, ...]] = {
    "terrain": (2 * len(TERRAIN_CELLS), GRID, GRID),
    "items": (len(ITEM_CELLS), GRID, GRID),
    "targets": (len(TARGET_CELLS), GRID, GRID),
    "goals": (len(GOAL_CELLS), GRID, GRID),
    "agent": (32,),
    "destination": (9,),
}
OBS_KEYS: tuple[str, ...] = tuple(OBS_SHAPES)

#: Terrain codes (the ``type`` channel holds code / 8).
TERRAIN_TYPES: dict[str, int] = {
    "void": 0,
    "platform": 1,
    "ramp": 2,
    "conveyor": 3,
    "collapsing": 4,
    "trampoline": 5,
    "archive": 6,
    "goal": 7,
    "destination": 8,
}
#: Item codes (the ``items`` channels hold code / 6).
ITEM_TYPES: dict[str, int] = {
    "none": 0,
    "conveyor": 1,
    "trampoline": 2,
    "collapsing": 3,
    "balloon": 4,
    "hammer": 5,
    "prop": 6,
}

#: Meaning of each float of ``agent`` (index = position). All clipped to [-1, 1].
AGENT_FEATURES: tuple[str, ...] = (
    "progress_x",  # 0: 2 * x / course_length - 1
    "pos_y",  # 1: y / 10 m
    "pos_z",  # 2: z / 10 m
    "yaw_sin",  # 3: facing direction (rotation)
    "yaw_cos",  # 4
    "vel_x",  # 5: velocity / 10 m/s
    "vel_y",  # 6
    "vel_z",  # 7
    "grounded",  # 8: animation state flags, 0/1
    "jumping",  # 9: airborne and rising
    "falling",  # 10: airborne and descending
    "knocked",  # 11: knocked back (controls disabled)
    "on_conveyor",  # 12
    "on_trampoline",  # 13
    "on_collapsing",  # 14
    "sprinting",  # 15
    "belt_vel_x",  # 16: surface velocity under the feet / 5 m/s
    "belt_vel_y",  # 17
    "archive_dx",  # 18: last archive point minus position / 20 m
    "archive_dy",  # 19
    "archive_dz",  # 20
    "next_goal_dx",  # 21: next goal (intermediate or destination) minus position / 20 m
    "next_goal_dy",  # 22
    "next_goal_dz",  # 23
    "next_goal_dist",  # 24: distance to the next goal / 50 m
    "height_above_floor",  # 25: feet above the floor below / 5 m (1 over void)
    "distance_from_cliff",  # 26: horizontal distance to the nearest floor edge / 5 m
    "goals_fraction",  # 27: fraction of goals reached
    "time_fraction",  # 28: step / max_episode_steps
    "prop_held",  # 29: 1 if a dash prop is held
    "cooldown",  # 30: remaining jump/attack/dash cooldown fraction
    "stay_fraction",  # 31: how long the racer has been stationary / stay limit
)
#: Meaning of each float of ``destination``. All clipped to [-1, 1].
DESTINATION_FEATURES: tuple[str, ...] = (
    "dx",  # destination centre minus racer position / 100 m
    "dy",
    "dz",
    "yaw_sin",  # rotation of the destination pad
    "yaw_cos",
    "tilt",  # pad tilt (0 = flat)
    "size_x",  # half-extents / 10 m
    "size_y",
    "size_z",
)

ACTION_NVEC: tuple[int, ...] = (3, 3, 2, 2, 2, 2, 8, 2)
ACTION_NAMES: tuple[str, ...] = (
    "move_x",
    "move_y",
    "jump",
    "sprint",
    "attack",
    "use_prop",
    "use_prop_dir",
    "idle",
)

#: Reward terms reported in ``info["reward_terms"]``; their sum is the step reward.
REWARD_TERMS: tuple[str, ...] = (
    "arrive_target",
    "arrive_goal",
    "arrive_destination",
    "goal_distance",
    "fall_or_wall",
    "stay",
    "time",
)
#: Keys of ``info["episode_metrics"]`` (present on the last step of an episode).
EPISODE_METRICS: tuple[str, ...] = (
    "success",
    "trapped",
    "unnecessary_jumps",
    "jumps",
    "unnecessary_jump_rate",
    "distance_from_cliff",
    "goal_reward",
    "total_reward",
    "episode_length",
)


def observation_space() -> spaces.Dict:
    """Return a fresh observation space of one racer (see the module docstring)."""
    boxes = {}
    for key, shape in OBS_SHAPES.items():
        low = -1.0 if key in ("terrain", "agent", "destination") else 0.0
        boxes[key] = spaces.Box(low=low, high=1.0, shape=shape, dtype=np.float32)
    return spaces.Dict(boxes)


def action_space() -> spaces.MultiDiscrete:
    """Return a fresh action space of one racer: ``MultiDiscrete([3,3,2,2,2,2,8,2])``."""
    return spaces.MultiDiscrete(np.array(ACTION_NVEC, dtype=np.int64))
