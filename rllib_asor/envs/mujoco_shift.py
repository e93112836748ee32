"""MuJoCo locomotion with per-episode dynamics shift (public ESCP / SRPO conventions).

`MujocoShiftEnv` owns a Gymnasium v5 env (HalfCheetah, Walker2d, Hopper, Ant), stores the
nominal model values once and rewrites the MuJoCo model on every reset (and, in the
non-stationary mode, every `switch_every` steps). Observation, action and reward are the
v5 env's own.

Parameters (names used in `params`, `fixed`, `info["dynamics"]`):

=========  =========================  ===================================================
name       model field                sampled value (ESCP)
=========  =========================  ===================================================
mass       body_mass                  multiplier 1.5^U(-3, 3)   (0.30 .. 3.38)
inertia    body_inertia               multiplier 1.5^U(-3, 3)
damping    dof_damping                multiplier 1.5^U(-3, 3)
friction   geom_friction              multiplier 1.5^U(-3, 3)
gravity    opt.gravity                multiplier 1.5^U(-3, 3)
wind       opt.wind[:2]               absolute (wx, wy) m/s, each U(-3, 3); sets
                                      opt.density = `air_density` (1.2) so that it acts
density    opt.density                absolute kg/m^3; fixed only (SRPO's `density_10`)
=========  =========================  ===================================================

One multiplier per parameter scales every element (`per_element=True` draws one per
element instead, as rand_param_envs/PEARL do). Modes:

- random (default): draw `params` (default mass, damping, wind) at every reset;
  `num_tasks=N` instead draws a pool of N parameter sets once (from `task_seed`) and picks one
  per episode, so `info["dynamics_id"]` is a small task index.
- non-stationary: `switch_every=K` redraws the dynamics after every K steps of an episode
  (ESCP uses 100): steps 1..K run under the first draw, K+1..2K under the second, ...
- fixed (evaluation): `fixed={"mass": 3.0}` or `dynamics="mass_x3"`; presets "original",
  "body_mass" (mass x3) and "density_10" (opt.density = 10) are the offline settings of SRPO.
  With `fixed`/`dynamics` given, nothing is sampled unless `params` is passed explicitly.

`info["dynamics"]` holds the current values, `info["dynamics_id"]` an int (task index with
`num_tasks`, else a stable 31-bit CRC32 of the rounded values; 0 = nominal), and
`info["dynamics_params"]` the sampled values as one float32 vector scaled to [-1, 1]
(`param_names` says which: a multiplier m as log_base(m) / log_scale_limit, per-element
multipliers by their mean log; wind as (wx, wy) / wind_limit; fixed values are left out),
what a policy conditioned on the dynamics (OSI) reads.
After a rewrite `mujoco.mj_setConst` refreshes the derived constants (subtree masses,
inverse weights) on a scratch MjData, so the episode's state is untouched.
"""

from __future__ import annotations

import re
import zlib
from collections.abc import Iterable, Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from game_env.gl import import_mujoco

mujoco = import_mujoco()  # loads no GL library (MUJOCO_GL=egl on a machine without libEGL)

MULTIPLIER_PARAMS = ("mass", "inertia", "damping", "friction", "gravity")
SAMPLED_PARAMS = (*MULTIPLIER_PARAMS, "wind")
ALL_PARAMS = (*SAMPLED_PARAMS, "density")
DEFAULT_PARAMS = ("mass", "damping", "wind")
_FIELDS = {
    "mass": "body_mass",
    "inertia": "body_inertia",
    "damping": "dof_damping",
    "friction": "geom_friction",
}
PRESETS: dict[str, dict[str, Any]] = {
    "original": {},
    "nominal": {},
    "body_mass": {"mass": 3.0},
    "density_10": {"density": 10.0},
}
_PRESET_RE = re.compile(r"^(mass|inertia|damping|friction|gravity)_x([0-9]*\.?[0-9]+)$")
BASE_IDS = ("HalfCheetah-v5", "Walker2d-v5", "Hopper-v5", "Ant-v5")


def parse_dynamics(name: str) -> dict[str, Any]:
    """Turn a preset name ("original", "body_mass", "density_10", "mass_x3", ...) into `fixed`."""
    if not isinstance(name, str):
        raise ValueError(f"dynamics={name!r} is not allowed; expected a string")
    if name in PRESETS:
        return dict(PRESETS[name])
    m = _PRESET_RE.match(name)
    if m:
        return {m.group(1): float(m.group(2))}
    m = re.match(r"^density_([0-9]*\.?[0-9]+)$", name)
    if m:
        return {"density": float(m.group(1))}
    raise ValueError(
        f"dynamics={name!r} is not allowed; expected one of {tuple(PRESETS)}, "
        "'<param>_x<multiplier>' with param in "
        f"{MULTIPLIER_PARAMS} (e.g. 'mass_x3'), or 'density_<kg/m^3>'"
    )


def _positive_number(key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{key}={value!r} is not allowed; expected a positive number")
    if not np.isfinite(value) or value <= 0:
        raise ValueError(f"{key}={value!r} is not allowed; expected a positive number")
    return float(value)


def _check_fixed(fixed: Mapping[str, Any], key: str = "fixed") -> dict[str, Any]:
    if not isinstance(fixed, Mapping):
        raise ValueError(f"{key}={fixed!r} is not allowed; expected a dict name -> value")
    out: dict[str, Any] = {}
    for name, value in fixed.items():
        if name not in ALL_PARAMS:
            raise ValueError(f"{key}[{name!r}] is not allowed; expected names from {ALL_PARAMS}")
        if name == "wind":
            try:
                w = np.atleast_1d(np.asarray(value, dtype=np.float64))
            except (TypeError, ValueError):
                w = np.array([np.nan])
            if w.shape not in ((1,), (2,)) or not np.all(np.isfinite(w)):
                raise ValueError(
                    f"{key}['wind']={value!r} is not allowed; expected a float (x wind) or (wx, wy)"
                )
            out["wind"] = np.array([w[0], w[1] if w.shape == (2,) else 0.0])
        elif name == "density":
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float, np.integer, np.floating))
                or not np.isfinite(value)
                or value < 0
            ):
                raise ValueError(
                    f"{key}['density']={value!r} is not allowed; expected a number >= 0"
                )
            out["density"] = float(value)
        else:
            try:
                v = np.asarray(value, dtype=np.float64)
            except (TypeError, ValueError):
                v = np.array(np.nan)
            if isinstance(value, bool) or not np.all(np.isfinite(v)) or np.any(v <= 0):
                raise ValueError(
                    f"{key}[{name!r}]={value!r} is not allowed; expected a positive multiplier"
                )
            out[name] = float(v) if v.ndim == 0 else v
    return out


class MujocoShiftEnv(gym.Env[np.ndarray, np.ndarray]):
    """A Gymnasium v5 MuJoCo env whose dynamics are redrawn per episode (see module doc).

    Args:
        base_id: the v5 env to wrap, one of BASE_IDS.
        params: names to sample per episode (subset of SAMPLED_PARAMS); None = DEFAULT_PARAMS,
            or () when `fixed`/`dynamics` is given.
        fixed: name -> value held fixed (multiplier; wind: (wx, wy) m/s; density: kg/m^3).
        dynamics: a preset name (see `parse_dynamics`), merged under `fixed`.
        switch_every: redraw the sampled params every K steps within an episode (None: never).
        num_tasks: draw a pool of this many parameter sets once and pick one per episode.
        task_seed: seed of the task pool.
        log_scale_limit: multipliers are scale_base ** U(-log_scale_limit, log_scale_limit).
        scale_base: the base of those multipliers.
        wind_limit: wind components are U(-wind_limit, wind_limit) m/s.
        air_density: opt.density used whenever wind is on (nominal models have 0).
        per_element: one multiplier per model element instead of one per parameter.
        max_episode_steps: time limit of the inner env (1000 like v5).
        env_kwargs: extra keyword arguments for `gym.make(base_id, ...)`.
        render_mode: passed to the inner env.
    """

    metadata = {"render_modes": ["human", "rgb_array", "depth_array"], "render_fps": 20}

    def __init__(
        self,
        base_id: str = "HalfCheetah-v5",
        params: Iterable[str] | None = None,
        fixed: Mapping[str, Any] | None = None,
        dynamics: str | None = None,
        switch_every: int | None = None,
        num_tasks: int | None = None,
        task_seed: int = 0,
        log_scale_limit: float = 3.0,
        scale_base: float = 1.5,
        wind_limit: float = 3.0,
        air_density: float = 1.2,
        per_element: bool = False,
        max_episode_steps: int = 1000,
        env_kwargs: Mapping[str, Any] | None = None,
        render_mode: str | None = None,
    ) -> None:
        if base_id not in BASE_IDS:
            raise ValueError(f"base_id={base_id!r} is not allowed; expected one of {BASE_IDS}")
        fixed_values = parse_dynamics(dynamics) if dynamics is not None else {}
        fixed_values.update(_check_fixed(fixed or {}))
        if params is None:
            params = () if (fixed or dynamics is not None) else DEFAULT_PARAMS
        if isinstance(params, str):
            params = (params,)
        params = tuple(params)
        for p in params:
            if p not in SAMPLED_PARAMS:
                raise ValueError(
                    f"params entry {p!r} is not allowed; expected names from {SAMPLED_PARAMS}"
                    + (" ('density' can only be fixed)" if p == "density" else "")
                )
        for key, value in (("switch_every", switch_every), ("num_tasks", num_tasks)):
            if value is not None and (
                isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1
            ):
                raise ValueError(f"{key}={value!r} is not allowed; expected None or an int >= 1")
        self.log_scale_limit = _positive_number("log_scale_limit", log_scale_limit)
        self.scale_base = _positive_number("scale_base", scale_base)
        self.wind_limit = _positive_number("wind_limit", wind_limit)
        self.air_density = _positive_number("air_density", air_density)
        self.params = tuple(p for p in params if p not in fixed_values)
        self.fixed = fixed_values
        self.switch_every = switch_every
        self.per_element = bool(per_element)
        self.base_id = base_id

        self.env = gym.make(
            base_id,
            max_episode_steps=max_episode_steps,
            render_mode=render_mode,
            disable_env_checker=True,
            **dict(env_kwargs or {}),
        )
        self.render_mode = render_mode
        self.metadata = dict(self.env.metadata)
        self.observation_space = self.env.observation_space
        self.action_space = self.env.action_space
        self.model: mujoco.MjModel = self.env.unwrapped.model
        self._scratch = mujoco.MjData(self.model)
        self.nominal: dict[str, np.ndarray] = {
            "body_mass": self.model.body_mass.copy(),
            "body_inertia": self.model.body_inertia.copy(),
            "dof_damping": self.model.dof_damping.copy(),
            "geom_friction": self.model.geom_friction.copy(),
            "gravity": self.model.opt.gravity.copy(),
            "wind": self.model.opt.wind.copy(),
            "density": np.array(self.model.opt.density),
        }
        self._rng = np.random.default_rng()
        self.tasks: list[dict[str, Any]] | None = None
        if num_tasks is not None:
            task_rng = np.random.default_rng(task_seed)
            self.tasks = [self._sample(task_rng) for _ in range(num_tasks)]
        self.dynamics: dict[str, Any] = {}
        self.dynamics_id = 0
        self._steps = 0

    # -- dynamics -------------------------------------------------------------------------
    def _sample(self, rng: np.random.Generator) -> dict[str, Any]:
        """One draw of the sampled params, merged with the fixed ones."""
        values: dict[str, Any] = {}
        for p in self.params:
            if p == "wind":
                values["wind"] = rng.uniform(-self.wind_limit, self.wind_limit, size=2)
            else:
                shape = self.nominal[_FIELDS.get(p, p)].shape if self.per_element else ()
                u = rng.uniform(-self.log_scale_limit, self.log_scale_limit, size=shape)
                values[p] = self.scale_base**u if self.per_element else float(self.scale_base**u)
        values.update(
            {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in self.fixed.items()}
        )
        return values

    def set_dynamics(self, values: Mapping[str, Any], dynamics_id: int | None = None) -> None:
        """Write `values` (name -> value; missing names = nominal) into the MuJoCo model now."""
        values = _check_fixed(values, "values")
        m, nom = self.model, self.nominal
        for p, field in _FIELDS.items():
            getattr(m, field)[:] = nom[field] * values.get(p, 1.0)
        m.opt.gravity[:] = nom["gravity"] * values.get("gravity", 1.0)
        m.opt.wind[:] = nom["wind"]
        density = float(nom["density"])
        if "wind" in values:
            m.opt.wind[:2] = values["wind"]
            density = self.air_density
        m.opt.density = values.get("density", density)
        mujoco.mj_setConst(m, self._scratch)
        self.dynamics = values
        self.dynamics_id = self._id(values) if dynamics_id is None else int(dynamics_id)

    @staticmethod
    def _id(values: Mapping[str, Any]) -> int:
        if not values:
            return 0
        text = ";".join(
            f"{k}={np.round(np.asarray(values[k]), 6).tolist()}" for k in sorted(values)
        )
        return zlib.crc32(text.encode()) & 0x7FFFFFFF  # fits int32

    def _draw(self) -> None:
        if self.tasks is not None:
            i = int(self._rng.integers(len(self.tasks)))
            self.set_dynamics(self.tasks[i], dynamics_id=i)
        else:
            self.set_dynamics(self._sample(self._rng))

    @property
    def param_names(self) -> tuple[str, ...]:
        """The entries of `info["dynamics_params"]` (wind gives `wind_x`, `wind_y`)."""
        names: list[str] = []
        for p in SAMPLED_PARAMS:
            if p in self.params:
                names += ["wind_x", "wind_y"] if p == "wind" else [p]
        return tuple(names)

    def dynamics_params(self) -> np.ndarray:
        """The sampled dynamics now as a float32 vector in [-1, 1] (module docstring);
        nominal values (before the first reset) give 0."""
        out: list[float] = []
        log_base = float(np.log(self.scale_base))
        for p in SAMPLED_PARAMS:
            if p not in self.params:
                continue
            value = self.dynamics.get(p)
            if p == "wind":
                wind = np.zeros(2) if value is None else np.asarray(value, dtype=np.float64)
                out += list(wind / self.wind_limit)
            else:
                m = 1.0 if value is None else np.asarray(value, dtype=np.float64)
                out.append(float(np.mean(np.log(m))) / log_base / self.log_scale_limit)
        return np.asarray(out, dtype=np.float32)

    def _info(self, info: dict[str, Any]) -> dict[str, Any]:
        info = dict(info)
        info["dynamics"] = {
            k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in self.dynamics.items()
        }
        info["dynamics_id"] = self.dynamics_id
        info["dynamics_params"] = self.dynamics_params()
        return info

    # -- gymnasium API --------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Draw (or, with options={"dynamics": {...}}, set) the dynamics, then reset."""
        super().reset(seed=seed)
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        options = dict(options or {})
        unknown = set(options) - {"dynamics"}
        if unknown:
            raise ValueError(f"options keys {sorted(unknown)} are not allowed; expected 'dynamics'")
        if options.get("dynamics") is not None:
            d = options["dynamics"]
            self.set_dynamics(parse_dynamics(d) if isinstance(d, str) else d)
        else:
            self._draw()
        self._steps = 0
        obs, info = self.env.reset(seed=seed)
        return obs, self._info(info)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if (
            self.switch_every is not None
            and self._steps > 0
            and self._steps % self.switch_every == 0
        ):
            self._draw()
        self._steps += 1
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, float(reward), terminated, truncated, self._info(info)

    def render(self) -> Any:
        return self.env.render()

    def close(self) -> None:
        self.env.close()


class HalfCheetahShiftEnv(MujocoShiftEnv):
    """HalfCheetah-v5 with dynamics shift."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(base_id="HalfCheetah-v5", **kwargs)


class Walker2dShiftEnv(MujocoShiftEnv):
    """Walker2d-v5 with dynamics shift."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(base_id="Walker2d-v5", **kwargs)


class HopperShiftEnv(MujocoShiftEnv):
    """Hopper-v5 with dynamics shift."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(base_id="Hopper-v5", **kwargs)


class AntShiftEnv(MujocoShiftEnv):
    """Ant-v5 with dynamics shift."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(base_id="Ant-v5", **kwargs)
