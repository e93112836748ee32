"""Procedurally generated Fall-Guys-like obstacle race in MuJoCo (no ray/torch import)."""

from game_env.spaces import action_space, observation_space

NUM_MAPS = 10

__all__ = ["NUM_MAPS", "action_space", "observation_space"]
