"""Env ids: import the modules that register ours, check an id exists, register it with Tune."""

from __future__ import annotations

import functools
import importlib
from typing import Any

# Modules whose import registers gymnasium ids; either may not exist (yet).
REGISTERING_MODULES = ("rllib_asor.envs", "game_env")


def import_registering_modules() -> None:
    """Import every module in REGISTERING_MODULES that can be imported."""
    for name in REGISTERING_MODULES:
        try:
            importlib.import_module(name)
        except ImportError:
            pass


def _in_tune_registry(env_id: str) -> bool:
    from ray.tune.registry import ENV_CREATOR, _global_registry

    return _global_registry.contains(ENV_CREATOR, env_id)


def env_exists(env_id: str) -> bool:
    """True if `env_id` is a gymnasium id (after our imports) or a Tune-registered env."""
    import gymnasium as gym

    import_registering_modules()
    return env_id in gym.registry or _in_tune_registry(env_id)


def known_ids(limit: int = 12) -> str:
    """A short list of ids to show in an error message (ours first)."""
    import gymnasium as gym

    import_registering_modules()
    ids = sorted(gym.registry)
    ours = [i for i in ids if i.startswith(("rllib_asor/", "game_env/"))]
    common = [i for i in ("CartPole-v1", "Pendulum-v1", "MountainCar-v0") if i in gym.registry]
    shown = (ours + common)[:limit]
    return ", ".join(shown) + f" (or any of the {len(ids)} gymnasium ids)"


def make_env(env_id: str, env_config: Any) -> Any:
    """Env creator run inside each Ray worker: register our ids there too, then gym.make."""
    import gymnasium as gym

    import_registering_modules()
    return gym.make(env_id, **dict(env_config or {}))


def register_with_tune(env_id: str) -> None:
    """Register a picklable creator for a gymnasium id, so env runners can build it.

    Ids already registered with Tune by someone else (e.g. a PettingZoo wrapper) are kept.
    """
    import gymnasium as gym
    from ray import tune

    import_registering_modules()
    if env_id in gym.registry and not _in_tune_registry(env_id):
        tune.register_env(env_id, functools.partial(make_env, env_id))
