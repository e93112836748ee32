"""studies/race_scale/run.py's per-iteration trace: the learning statistics a run's curve is
read against."""

from __future__ import annotations

import numpy as np

from studies.race_scale.run import TRACE_EVERY, trace_due, traced


def test_trace_keeps_the_numbers_of_the_policy_asor_and_race_sections_only() -> None:
    result = {
        "learners": {
            "default_policy": {"entropy": np.float32(1.5), "mean_kl_loss": 0.01, "on": True},
            "asor_disc.default_policy": {"lambda": 0.01, "per_map": {"a": 1.0}},
            "__all_modules__": {"num_trainable_parameters": 3},
        },
        "race": {"success_rate": 0.5, "episodes": 12},
        "env_runners": {"episode_return_mean": 3.0},
    }
    assert traced(result) == {
        "learners/default_policy/entropy": 1.5,
        "learners/default_policy/mean_kl_loss": 0.01,
        "learners/asor_disc.default_policy/lambda": 0.01,
        "race/success_rate": 0.5,
        "race/episodes": 12.0,
    }


def test_a_result_without_those_sections_traces_nothing() -> None:
    assert traced({"learners": {"default_policy": 1.0}, "race": None}) == {}


def test_a_trace_row_is_kept_once_per_scale_iteration_of_env_steps() -> None:
    trace: list[dict[str, float]] = []
    kept = []
    for steps in range(1024, 40_000, 1024):  # today's 1,024-step iterations
        if trace_due(steps, trace):
            trace.append({"env_steps": steps})
            kept.append(steps)
    assert kept == [1024, 1024 + TRACE_EVERY, 1024 + 2 * TRACE_EVERY]
    assert all(trace_due(s, [{"env_steps": s - TRACE_EVERY}]) for s in (TRACE_EVERY, 50_000))
