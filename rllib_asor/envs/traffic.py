"""Highway driving whose traffic density (the dynamics) is drawn per episode.

`HighwayDensityEnv` owns a highway-env `HighwayEnvFast` ("highway-fast-v0": 3 lanes, 5 Hz
simulation, 1 Hz decisions) and, at every reset, draws a density d from `densities` and sets
``vehicles_density = d`` (spacing between spawned cars shrinks as 1/d) and
``vehicles_count = round(base_vehicles_count * d)`` (more cars), so a denser episode really
has more vehicles around the ego car.

Observation: highway-env's Kinematics of the ego car and the `observed_vehicles - 1` nearest
others, features (presence, x, y, vx, vy), normalised and clipped to [-1, 1]; the ego row
holds its own (absolute) speed vx, vy, others are relative to the ego. Flattened to a
Box(-1, 1, (observed_vehicles * 5,)) by default (``flatten=False`` keeps (N, 5)).
Actions: DiscreteMetaAction (0 LANE_LEFT, 1 IDLE, 2 LANE_RIGHT, 3 FASTER, 4 SLOWER).
Episodes last `duration` decisions (30 by default) or end on a crash.

`info` holds highway-env's own keys (speed, crashed, rewards, ...) plus `density`,
`vehicles_count` and `dynamics_id` = round(100 * density) (density in percent).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from highway_env.envs.highway_env import HighwayEnvFast

DEFAULT_DENSITIES = (0.5, 1.0, 1.5, 2.0)
FEATURES = ("presence", "x", "y", "vx", "vy")
# keys users may not override through `config` (the wrapper owns them)
_OWNED_KEYS = ("observation", "action", "vehicles_density", "vehicles_count", "duration")


def _check_density(key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{key}={value!r} is not allowed; expected a positive number")
    if not np.isfinite(value) or value <= 0:
        raise ValueError(f"{key}={value!r} is not allowed; expected a positive number")
    return float(value)


def _check_int(key: str, value: Any, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise ValueError(f"{key}={value!r} is not allowed; expected an int >= {low}")
    return int(value)


class HighwayDensityEnv(gym.Env[np.ndarray, np.int64]):
    """highway-fast with the traffic density drawn per episode (see module doc).

    Args:
        densities: the set a density is drawn from at each reset (uniformly).
        density: fix the density (evaluation); overrides `densities`.
        base_vehicles_count: vehicles spawned at density 1.0 (highway-fast: 20).
        duration: episode length in decisions (1 Hz).
        observed_vehicles: rows of the Kinematics observation (ego included).
        flatten: flatten the (observed_vehicles, 5) observation to 1-D.
        config: extra highway-env config entries (e.g. {"lanes_count": 4}).
        render_mode: passed to highway-env ("rgb_array" needs pygame).
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 1}

    def __init__(
        self,
        densities: Iterable[float] = DEFAULT_DENSITIES,
        density: float | None = None,
        base_vehicles_count: int = 20,
        duration: int = 30,
        observed_vehicles: int = 5,
        flatten: bool = True,
        config: Mapping[str, Any] | None = None,
        render_mode: str | None = None,
    ) -> None:
        self.densities = tuple(_check_density("densities", d) for d in densities)
        if not self.densities:
            raise ValueError("densities=() is not allowed; expected at least one positive number")
        self.fixed_density = None if density is None else _check_density("density", density)
        self.base_vehicles_count = _check_int("base_vehicles_count", base_vehicles_count, 1)
        self.duration = _check_int("duration", duration, 1)
        self.observed_vehicles = _check_int("observed_vehicles", observed_vehicles, 1)
        self.flatten = bool(flatten)
        extra = dict(config or {})
        for key in extra:
            if key in _OWNED_KEYS:
                raise ValueError(
                    f"config[{key!r}] is not allowed; set it through the env's own arguments "
                    f"(owned keys: {_OWNED_KEYS})"
                )
        cfg = {
            "observation": {
                "type": "Kinematics",
                "vehicles_count": self.observed_vehicles,
                "features": list(FEATURES),
                "normalize": True,
                "clip": True,
                "absolute": False,
                "order": "sorted",
            },
            "action": {"type": "DiscreteMetaAction"},
            "duration": self.duration,
            "vehicles_density": 1.0,
            "vehicles_count": self.base_vehicles_count,
            **extra,
        }
        self.env = HighwayEnvFast(config=cfg, render_mode=render_mode)
        self.render_mode = render_mode
        shape = (
            (self.observed_vehicles * len(FEATURES),)
            if self.flatten
            else (self.observed_vehicles, len(FEATURES))
        )
        self.observation_space = spaces.Box(-1.0, 1.0, shape, np.float32)
        self.action_space = spaces.Discrete(int(self.env.action_space.n))
        self.density = self.fixed_density if self.fixed_density is not None else self.densities[0]

    @property
    def vehicles_count(self) -> int:
        """Other vehicles spawned at the current density."""
        return max(1, round(self.base_vehicles_count * self.density))

    def _obs(self, obs: np.ndarray) -> np.ndarray:
        obs = np.clip(np.nan_to_num(np.asarray(obs, dtype=np.float32)), -1.0, 1.0)
        return obs.reshape(self.observation_space.shape)

    def _info(self, info: dict[str, Any]) -> dict[str, Any]:
        info = dict(info)
        info["density"] = self.density
        info["vehicles_count"] = self.vehicles_count
        info["dynamics_id"] = round(100 * self.density)
        return info

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Draw the density (or take options={"density": d}), configure, reset highway-env."""
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - {"density"}
        if unknown:
            raise ValueError(f"options keys {sorted(unknown)} are not allowed; expected 'density'")
        if options.get("density") is not None:
            self.density = _check_density("density", options["density"])
        elif self.fixed_density is not None:
            self.density = self.fixed_density
        else:
            self.density = self.densities[int(self.np_random.integers(len(self.densities)))]
        self.env.configure(
            {"vehicles_density": self.density, "vehicles_count": self.vehicles_count}
        )
        obs, info = self.env.reset(
            seed=None if seed is None else int(self.np_random.integers(2**31))
        )
        return self._obs(obs), self._info(info)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if not self.action_space.contains(action):
            raise ValueError(
                f"action={action!r} is not allowed; expected an int in [0, {self.action_space.n - 1}]"
            )
        obs, reward, terminated, truncated, info = self.env.step(int(action))
        return self._obs(obs), float(reward), bool(terminated), bool(truncated), self._info(info)

    def render(self) -> Any:
        return self.env.render()

    def close(self) -> None:
        self.env.close()
