"""Procedurally generated Fall-Guys-like obstacle race in MuJoCo (no ray/torch import).

``gymnasium.make("game_env/ObstacleRace-v0", map_id=...)`` for one racer,
``game_env.parallel_env(num_racers=N, map_id=...)`` for a PettingZoo ParallelEnv.
Importing it loads no GL library: MuJoCo's rendering backend is chosen at the first render
(`game_env.gl`), so a machine without any GL can simulate and train.
"""

from game_env.gl import import_mujoco

import_mujoco()  # before any module of ours imports it: no GL library is loaded at import

import gymnasium  # noqa: E402

from game_env.generator import generate_course  # noqa: E402
from game_env.maps import MAPS, NUM_MAPS  # noqa: E402
from game_env.parallel import RaceParallelEnv, parallel_env  # noqa: E402
from game_env.spaces import action_space, observation_space  # noqa: E402

ENV_ID = "game_env/ObstacleRace-v0"
if ENV_ID not in gymnasium.registry:
    # Gymnasium's passive checker is a wrapper on every step; tests run its full check_env.
    gymnasium.register(id=ENV_ID, entry_point="game_env.env:ObstacleRaceEnv", disable_env_checker=True)

__all__ = [
    "ENV_ID",
    "MAPS",
    "NUM_MAPS",
    "RaceParallelEnv",
    "action_space",
    "generate_course",
    "observation_space",
    "parallel_env",
]
