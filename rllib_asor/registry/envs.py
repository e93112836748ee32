"""Our env ids for RLlib: import the modules that register them, check an id exists, make one.
`env_names.register_env` registers any env name with Tune so that env runners can build it."""

from __future__ import annotations

import importlib
from typing import Any

from rllib_asor import ray_compat as compat

# Modules whose import registers gymnasium ids; either may not exist (yet).
REGISTERING_MODULES = ("rllib_asor.envs", "game_env")


def import_registering_modules() -> None:
    """Import every module in REGISTERING_MODULES that can be imported."""
    for name in REGISTERING_MODULES:
        try:
            importlib.import_module(name)
        except ImportError:
            pass


def race_creators() -> dict[str, Any]:
    """Tune name -> creator of the race envs (`rllib_asor.race.config`); {} without game_env."""
    try:
        import game_env  # noqa: F401
        from rllib_asor.race import config as race
    except ImportError:
        return {}
    return {race.SINGLE_ENV: race.make_single_race_env, race.MULTI_ENV: race.make_multi_race_env}


def register_race_envs() -> None:
    """`rllib_asor.race.config.register_race_envs()` when game_env is installed.

    The race's own creators hand `max_episode_steps` to the env (a plain `gym.make` would
    only wrap a TimeLimit the env does not see, losing the end-of-episode metrics) and add
    the multi-racer PettingZoo env `game_env/ObstacleRaceMulti-v0`.
    """
    if race_creators():
        from rllib_asor.race.config import register_race_envs as register

        register()


def in_tune_registry(env_id: str) -> bool:
    """True if Tune has a creator registered under `env_id`."""
    from ray.tune.registry import ENV_CREATOR

    return compat.tune_registry_contains(ENV_CREATOR, env_id)


def env_exists(env_id: str) -> bool:
    """True if `env_id` is a gymnasium id (after our imports) or a Tune-registered env."""
    import gymnasium as gym

    import_registering_modules()
    register_race_envs()
    return env_id in gym.registry or in_tune_registry(env_id)


def known_ids(limit: int = 12) -> str:
    """A short list of ids to show in an error message (ours first)."""
    import gymnasium as gym

    import_registering_modules()
    ids = sorted(gym.registry)
    ours = [i for i in ids if i.startswith(("rllib_asor/", "game_env/"))]
    ours += [i for i in race_creators() if i not in ours]
    common = [i for i in ("CartPole-v1", "Pendulum-v1", "MountainCar-v0") if i in gym.registry]
    shown = (ours + common)[:limit]
    return ", ".join(shown) + f" (or any of the {len(ids)} gymnasium ids)"


def make_env(env_id: str, env_config: Any) -> Any:
    """Env creator run inside each Ray worker: register our ids there too, then gym.make."""
    import gymnasium as gym

    import_registering_modules()
    creator = race_creators().get(env_id)
    if creator is not None:
        return creator(env_config)
    return gym.make(env_id, **dict(env_config or {}))
