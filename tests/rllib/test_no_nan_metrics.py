"""No metric is ever NaN: a short real SAC+ASOR and PPO+ASOR Learner update (built in this
process, no Ray started) reports only finite numbers, and a metric that does not apply
(`critic_ev` without episode chunks, i.e. off-policy) is absent."""

from __future__ import annotations

import math
from typing import Any

from ray.rllib.utils.metrics.metrics_logger import MetricsLogger

from rllib_asor.rllib.callbacks import (
    AsorMetricsCallback,
    DropNaNLearnerStatsCallback,
    lift_asor_metrics,
)
from tests.rllib import test_glue_behaviour as ppo
from tests.rllib import test_soft_q_glue as sac


def _leaves(tree: Any, path: str = "") -> dict[str, float]:
    """Every number in the Learner results (MetricsLogger stats peeked), by its path."""
    if hasattr(tree, "peek"):
        tree = tree.peek()
    if isinstance(tree, dict):
        out: dict[str, float] = {}
        for k, v in tree.items():
            out.update(_leaves(v, f"{path}/{k}"))
        return out
    if isinstance(tree, int | float) and not isinstance(tree, bool):
        return {path: float(tree)}
    if isinstance(tree, list | tuple):  # a window of values
        return {f"{path}/{i}": v for i, x in enumerate(tree) for v in _leaves(x).values()}
    return {}


def _reported(results: Any) -> dict[str, Any]:
    """The Learner's results as the Algorithm reports them: aggregated into a root
    MetricsLogger under `learners` and reduced, as `Algorithm.training_step` does."""
    root = MetricsLogger(root=True)
    root.aggregate([results], key="learners")
    return root.reduce(compile=True)


RLLIB_ONCE = ("num_trainable_parameters", "num_non_trainable_parameters")
"""RLlib's own, logged once at build: NaN in every later iteration (RLlib 2.60)."""


def _no_nan(results: Any) -> dict[str, Any]:
    reported = _reported(results)
    leaves = _leaves(reported)
    assert leaves
    bad = sorted(k for k, v in leaves.items() if math.isnan(v) and not k.endswith(RLLIB_ONCE))
    assert not bad, f"NaN metrics: {bad}"
    # What Tune receives, after our callback: not one NaN, RLlib's own included.
    AsorMetricsCallback().on_train_result(result=reported)
    assert not [k for k, v in _leaves(reported).items() if math.isnan(v)]
    learners: dict[str, dict[str, float]] = {}
    for key, v in leaves.items():
        parts = key.strip("/").split("/")[1:]  # under "learners"
        if len(parts) == 2:
            learners.setdefault(parts[0], {})[parts[1]] = v
    lifted = lift_asor_metrics({"learners": learners})
    assert lifted and all(math.isfinite(v) for v in lifted.values())
    return lifted


def test_sac_asor_update_reports_no_nan_and_no_critic_ev() -> None:
    lrn = sac.sac_learner(lambda_warmup=False)
    for i in range(3):
        lifted = _no_nan(sac.update(lrn, sac.transitions(seed=i), steps=1000 * (i + 1)))
    assert "critic_ev" not in lifted  # no episode chunks off-policy: absent, not NaN
    assert {"bonus_share", "potential_share", "js_estimate", "active"} <= set(lifted)


def test_ppo_asor_update_reports_no_nan_and_a_finite_critic_ev() -> None:
    lrn = ppo.learner()
    for i in range(3):
        lifted = _no_nan(ppo.update(lrn, ppo.episodes(i), step=60 * (i + 1)))
    assert "critic_ev" in lifted and "archive_states" in lifted


def test_a_plain_run_drops_rllibs_nan_learner_stats_too() -> None:
    result = {"learners": {"default_policy": {"num_trainable_parameters": float("nan"),
                                              "policy_loss": 0.5}},
              "env_runners": {"episode_return_mean": float("nan")}}  # fmt: skip
    DropNaNLearnerStatsCallback().on_train_result(result=result)
    assert result["learners"] == {"default_policy": {"policy_loss": 0.5}}
    # Outside `learners` nothing is touched: a stop criterion may name it.
    assert math.isnan(result["env_runners"]["episode_return_mean"])
