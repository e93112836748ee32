"""Whether a comparison may give a verdict at all: runs that are smoke runs (`SMOKE_KEY`), an
arm whose policy never updated, or a treatment whose ASOR never ran get "no verdict" instead.

Read from RLlib's result rows: a Learner that updated a module reports
``learners/__all_modules__/num_env_steps_trained_lifetime`` and
``learners/<module>/num_module_steps_trained_lifetime`` (> 0); an RLlib result row without any
learner counter (``timers/training_step`` present, no ``learners/...``) is a run whose Learner
never updated, e.g. SAC before ``num_steps_sampled_before_learning_starts``. ASOR ran when some
row has an ASOR metric (``asor/...``, or a ``learners/asor_disc.<policy>/...`` module). Rows
that are not RLlib's (a plain Tune function, hand-made results) are not judged.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from rllib_asor.report.results import Trial, asor_mode

SMOKE_VERDICT = "smoke run (--test): no verdict"
ENV_STEPS = ("num_env_steps_trained_lifetime", "num_env_steps_trained")
MODULE_STEPS = ("num_module_steps_trained_lifetime", "num_module_steps_trained")
RLLIB_ROW = ("timers/training_step", "num_training_step_calls_per_iteration")
"""Keys every RLlib `Algorithm.train()` result has (a new-stack run's, with or without Learner)."""
AUX_MODULES = ("asor_disc.", "asor_proxy.", "__all_modules__")
"""Learner module ids that are not a policy (ASOR's own modules; the sum over modules)."""


def _number(v: Any) -> float | None:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        return None
    return float(v)


def trained_steps(trial: Trial) -> float | None:
    """Env steps the trial's Learner trained (the largest count reported; module steps of a
    policy where no env-step count is reported); 0 for RLlib rows with no learner counter at
    all; None when the rows are not RLlib's (nothing to judge)."""
    env: list[float] = []
    module: list[float] = []
    rllib = False
    for row in trial.rows:
        for key, value in row.items():
            rllib = rllib or key in RLLIB_ROW
            v = _number(value)
            if v is None:
                continue
            parts = key.split("/")
            if parts[-1] in ENV_STEPS:
                env.append(v)
            elif (
                parts[-1] in MODULE_STEPS
                and len(parts) == 3
                and parts[0] == "learners"
                and not parts[1].startswith(AUX_MODULES)
            ):
                module.append(v)
    if env:
        return max(env)
    if module:
        return max(module)
    return 0.0 if rllib else None


def asor_ran(trial: Trial) -> bool:
    """Whether any row has an ASOR metric (``asor/...`` anywhere, or ASOR's Learner modules)."""
    for row in trial.rows:
        for key in row:
            if key.startswith("asor/") or "/asor/" in key or "/asor_disc." in key:
                return True
    return False


def withheld(groups: Sequence[Any], smoke: bool = False) -> str | None:
    """Why the comparison of `groups` (baseline and treatment, `grouping.Group`) gets no verdict:
    a smoke run, an arm with a trial that never updated its policy, or an ASOR arm with a trial
    that trained without ASOR running; None when nothing stands in the way."""
    reasons = []
    for g in groups:
        steps = [trained_steps(t) for t in g.trials]
        never = sum(s == 0 for s in steps)
        if never:
            reasons.append(
                f"{g.label} never updated its policy (0 env steps trained in {never} of "
                f"{len(steps)} trials)"
            )
    for g in groups:
        if not any(asor_mode(t.params) is not None for t in g.trials):
            continue
        silent = sum(
            1
            for t in g.trials
            if asor_mode(t.params) is not None and (trained_steps(t) or 0) > 0 and not asor_ran(t)
        )
        if silent:
            reasons.append(
                f"ASOR never ran in {g.label} (no asor/ metrics in {silent} of {g.n} trials)"
            )
    if smoke:
        return SMOKE_VERDICT + (f" ({'; '.join(reasons)})" if reasons else "")
    return "no verdict: " + "; ".join(reasons) if reasons else None
