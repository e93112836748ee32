"""Termination rules of model rollouts, per env (MOPO's static functions).

Sources: `AIDefender/SRPO offlinerl/utils/net/terminal_check.py` (`termination_fn_hopper`,
`termination_fn_walker2d`, `termination_fn_halfcheetah`) and `xionghuichen/MAPLE
maple/policy/static/hopper.py`. They are the healthy rules of Gymnasium's v5 envs on the
observation (which omits the x position): Hopper obs[0] = torso height, obs[1] = angle.
One correction: the port writes `np.abs(next_obs[:, 1:] < 100)` (the abs of a boolean); the
v5 env's rule, used here, is |obs[1:]| < 100.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

TerminationFn = Callable[[np.ndarray], np.ndarray]
"""next observations [N, obs_dim] → terminated [N] (bool)."""


def hopper(next_obs: np.ndarray) -> np.ndarray:
    """Not healthy: non-finite, |obs[1:]| ≥ 100, height ≤ 0.7 or |angle| ≥ 0.2."""
    height, angle = next_obs[:, 0], next_obs[:, 1]
    healthy = (
        np.isfinite(next_obs).all(-1)
        & (np.abs(next_obs[:, 1:]) < 100).all(-1)
        & (height > 0.7)
        & (np.abs(angle) < 0.2)
    )
    return ~healthy


def walker2d(next_obs: np.ndarray) -> np.ndarray:
    """Not healthy: outside ±100, height ∉ (0.8, 2.0) or angle ∉ (−1, 1)."""
    height, angle = next_obs[:, 0], next_obs[:, 1]
    healthy = (
        np.isfinite(next_obs).all(-1)
        & (np.abs(next_obs) < 100).all(-1)
        & (height > 0.8)
        & (height < 2.0)
        & (angle > -1.0)
        & (angle < 1.0)
    )
    return ~healthy


def halfcheetah(next_obs: np.ndarray) -> np.ndarray:
    """HalfCheetah never falls: only non-finite or out-of-range (±100) states end."""
    return ~(np.isfinite(next_obs).all(-1) & (np.abs(next_obs) < 100).all(-1))


RULES: dict[str, TerminationFn] = {
    "hopper": hopper,
    "walker2d": walker2d,
    "halfcheetah": halfcheetah,
}


def register_termination(key: str, fn: TerminationFn) -> None:
    """Use `fn` for the model rollouts of env ids containing `key` (case-insensitive): the rule
    of a user's own env. Registered in the process that builds the algorithm (a Python
    `config.build_algo()`; under Tune, at import of the module that registers the env)."""
    if not key:
        raise ValueError("register_termination: key='' is invalid: allowed a non-empty string")
    RULES[key.lower()] = fn


def termination_fn(env_id: str) -> TerminationFn:
    """The rule for an env id (`rllib_asor/HopperShift-v0`, `Hopper-v5`, ...), matched by name
    as the port's `is_terminal`; ValueError for envs without one."""
    name = env_id.lower()
    for key in sorted(RULES, key=len, reverse=True):
        if key in name:
            return RULES[key]
    raise ValueError(
        f"env={env_id!r} has no model-rollout termination rule: allowed envs whose id contains "
        f"{' | '.join(RULES)} (a user's env: register_termination(key, fn) first)"
    )
