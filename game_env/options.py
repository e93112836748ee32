"""Validation of env arguments and actions (bad input -> ValueError naming value and range)."""

from __future__ import annotations

import operator
import warnings
from typing import Any

import numpy as np

from game_env.maps import NUM_MAPS, check_map_id
from game_env.spaces import ACTION_NVEC

NVEC = np.array(ACTION_NVEC)
COURSE_SEEDS = 1000  # course seeds drawn per reset when none is fixed
RESET_OPTIONS = ("map_id", "course_seed")


MapChoice = int | tuple[int, ...] | None
"""A fixed map, maps to draw from per reset, or None (all maps)."""


def check_map_choice(map_id: Any) -> MapChoice:
    """An int 0..9; a non-empty list of them (one drawn per reset); or None/"random" (any of
    the ten drawn per reset) -> int, tuple of distinct ints, or None."""
    if map_id is None or (isinstance(map_id, str) and map_id == "random"):
        return None
    if isinstance(map_id, (list, tuple)):
        if not map_id:
            raise ValueError(
                "map_id=[] is not valid; allowed: an int in 0..9, a non-empty list of them, "
                "or None/'random'"
            )
        maps = tuple(dict.fromkeys(check_map_id(m) for m in map_id))
        return maps[0] if len(maps) == 1 else maps
    if isinstance(map_id, str):
        raise ValueError(
            f"map_id={map_id!r} is not valid; allowed: an int in 0..9, a list of them, "
            "or None/'random'"
        )
    return check_map_id(map_id)


def first_map(choice: MapChoice) -> int:
    """The map a fresh env loads before its first reset."""
    if choice is None:
        return 0
    return choice if isinstance(choice, int) else choice[0]


def check_positive_int(name: str, value: Any, low: int = 1, high: int | None = None) -> int:
    """Validate an int argument in [low, high]."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name}={value!r} is not valid; allowed: an int >= {low}"
                         + (f" and <= {high}" if high is not None else ""))
    if value < low or (high is not None and value > high):
        rng = f"{low}..{high}" if high is not None else f">= {low}"
        raise ValueError(f"{name}={value!r} is out of range; allowed: {rng}")
    return int(value)


def check_course_seed(seed: Any) -> int | None:
    """None (a course seed drawn per reset) or an int >= 0."""
    if seed is None:
        return None
    return check_positive_int("course_seed", seed, low=0)


STEP_INFOS = ("full", "lean")
"""``step_info`` values: "full" (every step's info has ``reward_terms``; the Gymnasium env's has
running ``episode_metrics`` too), "lean" (``reward_terms`` nowhere, ``episode_metrics`` only in
the info of the step the env itself ends the episode on)."""


def check_step_info(value: Any) -> str:
    if value not in STEP_INFOS:
        raise ValueError(f"step_info={value!r} is not valid; allowed: one of {STEP_INFOS}")
    return value


def check_render_mode(mode: Any) -> str | None:
    if mode not in (None, "rgb_array"):
        raise ValueError(f"render_mode={mode!r} is not supported; allowed: None or 'rgb_array'")
    return mode


def check_reset_options(options: Any) -> dict[str, Any]:
    """``reset(options=...)``: None or a dict; ``map_id``/``course_seed`` values are validated."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise ValueError(f"options={options!r} is not valid; allowed: None or a dict with keys {RESET_OPTIONS}")
    bad = [k for k in options if k not in RESET_OPTIONS]
    if bad:  # ignored (PettingZoo's API test passes arbitrary options), but said
        warnings.warn(f"reset options {bad!r} are ignored; known keys: {RESET_OPTIONS}", stacklevel=3)
    out: dict[str, Any] = {}
    if "map_id" in options:
        out["map_id"] = check_map_id(options["map_id"])
    if "course_seed" in options:
        out["course_seed"] = check_course_seed(options["course_seed"])
    return out


_NVEC_LIST = list(ACTION_NVEC)


def check_action(action: Any) -> list[int]:
    """One racer's action -> list of 8 ints, or ValueError naming the action."""
    vals = None
    if type(action) is np.ndarray and action.shape == (8,) and action.dtype.kind in "iu":
        vals = action.tolist()
    else:
        try:
            a = np.asarray(action)
            if a.shape == (8,) and (a.dtype.kind in "iu" or (a.dtype.kind == "f" and np.all(a == np.round(a)))):
                vals = [int(v) for v in a.tolist()]
        except (TypeError, ValueError, OverflowError):
            vals = None
    if vals is None or min(vals) < 0 or not all(map(operator.lt, vals, _NVEC_LIST)):
        raise ValueError(f"action {action!r} is outside the action space MultiDiscrete({_NVEC_LIST})")
    return vals


__all__ = ["NUM_MAPS", "check_action", "check_map_choice"]
