"""Gymnasium ids of our cross-dynamics envs. Each env module adds its ids to `ENV_IDS`."""

from __future__ import annotations

import gymnasium as gym

# id -> "module:Class"; kept in one table so the CLI can list what exists.
ENV_IDS: dict[str, str] = {
    "rllib_asor/LavaWorld-v0": "rllib_asor.envs.lava:LavaWorldEnv",
}


def register_envs() -> None:
    """Register every id in ENV_IDS with gymnasium (idempotent)."""
    for env_id, entry_point in ENV_IDS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point=entry_point)
