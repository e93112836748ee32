"""Env ids, one table for every process: our gymnasium ids (`ENV_IDS`, registered when
`rllib_asor` is imported), the race's Tune names (`rllib_asor.race.config.RACE_ENVS`), a check
that an id exists, and the creator Ray's env runners call. `env_names.register_env` registers
any other env name with Tune so that env runners can build it."""

from __future__ import annotations

import importlib
from typing import Any

from rllib_asor import ray_compat as compat

ENV_IDS: dict[str, str] = {
    "rllib_asor/LavaWorld-v0": "rllib_asor.envs.lava:LavaWorldEnv",
    "rllib_asor/HalfCheetahShift-v0": "rllib_asor.envs.mujoco_shift:HalfCheetahShiftEnv",
    "rllib_asor/Walker2dShift-v0": "rllib_asor.envs.mujoco_shift:Walker2dShiftEnv",
    "rllib_asor/HopperShift-v0": "rllib_asor.envs.mujoco_shift:HopperShiftEnv",
    "rllib_asor/AntShift-v0": "rllib_asor.envs.mujoco_shift:AntShiftEnv",
    "rllib_asor/HighwayDensity-v0": "rllib_asor.envs.traffic:HighwayDensityEnv",
}
"""Our cross-dynamics envs (`rllib_asor.envs`): gymnasium id -> "module:Class"."""
REGISTERING_MODULES = ("game_env",)
"""Modules whose import registers further gymnasium ids; one may not be installed."""


def register_envs() -> None:
    """Register every id in ENV_IDS with gymnasium (idempotent; entry points only, cheap)."""
    import gymnasium as gym

    for env_id, entry_point in ENV_IDS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point=entry_point)


def import_registering_modules() -> None:
    """Register our ids and import every module in REGISTERING_MODULES that can be imported."""
    register_envs()
    for name in REGISTERING_MODULES:
        try:
            importlib.import_module(name)
        except ImportError:
            pass


def race_creators() -> dict[str, Any]:
    """Tune name -> creator of the race envs (`rllib_asor.race.config.RACE_ENVS`); {} without
    game_env."""
    try:
        import game_env  # noqa: F401
        from rllib_asor.race import config as race
    except ImportError:
        return {}
    return dict(race.RACE_ENVS)


def in_tune_registry(env_id: str) -> bool:
    """True if Tune has a creator registered under `env_id`."""
    from ray.tune.registry import ENV_CREATOR

    return compat.tune_registry_contains(ENV_CREATOR, env_id)


def env_exists(env_id: str) -> bool:
    """True if `env_id` is a gymnasium id (after our imports) or a Tune-registered env."""
    import gymnasium as gym

    import_registering_modules()
    if race_creators():  # the race's Tune names (`race.config.register_race_envs`): its creators
        # hand `max_episode_steps` to the env (a plain `gym.make` would only wrap a TimeLimit the
        # env does not see, losing the end-of-episode metrics) and add the multi-racer env
        from rllib_asor.race.config import register_race_envs

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
