"""Gymnasium ids of our cross-dynamics envs. Each env module adds its ids to `ENV_IDS`."""

from __future__ import annotations

import gymnasium as gym

# id -> "module:Class"; kept in one table so the CLI can list what exists.
ENV_IDS: dict[str, str] = {
    "rllib_asor/LavaWorld-v0": "rllib_asor.envs.lava:LavaWorldEnv",
    "rllib_asor/HalfCheetahShift-v0": "rllib_asor.envs.mujoco_shift:HalfCheetahShiftEnv",
    "rllib_asor/Walker2dShift-v0": "rllib_asor.envs.mujoco_shift:Walker2dShiftEnv",
    "rllib_asor/HopperShift-v0": "rllib_asor.envs.mujoco_shift:HopperShiftEnv",
    "rllib_asor/AntShift-v0": "rllib_asor.envs.mujoco_shift:AntShiftEnv",
    "rllib_asor/HighwayDensity-v0": "rllib_asor.envs.traffic:HighwayDensityEnv",
}


def register_envs() -> None:
    """Register every id in ENV_IDS with gymnasium (idempotent)."""
    for env_id, entry_point in ENV_IDS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point=entry_point)
