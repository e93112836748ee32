"""Lift ASOR's Learner statistics into the results as `asor/<name>`.

The Learner logs them under its module ids (`learners/asor_disc.<policy>/...`); users read
`asor/disc_loss`, `asor/aug_reward_mean`, ... (single policy) or `asor/<policy>/...`. A metric
that does not apply (`critic_ev` without episode chunks: SAC, ESCP, CQL) is absent; a value
that is not a finite number is never lifted.
"""

from __future__ import annotations

import math
from typing import Any

from ray.rllib.callbacks.callbacks import RLlibCallback

from rllib_asor.algorithms.common import actor_shutdown
from rllib_asor.rllib.learners import ASOR_PREFIX

# Every trainable the CLI or `with_asor` builds unpickles one of the callbacks below, so this
# runs in its process: its env runners are dead before its `stop()` returns and Tune frees the
# trial's placement group, and in a Ray actor a SIGTERM never raises inside a finalizer (no
# "Exception ignored ... SystemExit: 1" at shutdown; actor_shutdown's docstring has the cause).
actor_shutdown.install()

ASOR_METRICS = frozenset(
    {
        # discriminator update (rllib_asor.asor.discriminator.discriminator_loss)
        "disc_loss", "disc_acc_real", "disc_acc_fake", "disc_bce_real", "disc_bce_fake",
        "disc_entropy", "js_estimate", "disc_grad_penalty", "disc_logit_norm",
        # reward augmentation (rllib_asor.asor.update)
        "lambda", "reward_scale", "real_fraction", "aug_reward_mean", "aug_reward_min",
        "aug_reward_max", "aug_reward_abs_mean", "bonus_share", "bonus_mean", "env_reward_mean",
        "value_mean", "value_real_mean", "omega_batch_mean", "omega_real_mean",
        "omega_generated_mean", "archive_states", "critic_ev", "active", "potential", "potential_share",
        "share_capped",
        # proxies
        "rnd_loss", "ensemble_loss",
    }
)  # fmt: skip


def lift_asor_metrics(result: dict[str, Any]) -> dict[str, Any]:
    """Collect `learners/asor_*.<pid>/*` into a dict keyed by pid (flat for one policy)."""
    per_policy: dict[str, dict[str, Any]] = {}
    for module_id, stats in (result.get("learners") or {}).items():
        if module_id.startswith(ASOR_PREFIX) and isinstance(stats, dict):
            pid = module_id[len(ASOR_PREFIX) :]
            per_policy.setdefault(pid, {}).update(
                {k: x for k, v in stats.items() if k in ASOR_METRICS
                 if (x := _finite(v)) is not None}
            )  # fmt: skip
    for stats in per_policy.values():
        if "disc_acc_real" in stats and "disc_acc_fake" in stats:
            stats["disc_acc"] = 0.5 * (stats["disc_acc_real"] + stats["disc_acc_fake"])
    if len(per_policy) == 1:
        return next(iter(per_policy.values()))
    return per_policy


def _finite(value: Any) -> float | None:
    try:
        x = float(value)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def drop_nan_learner_stats(result: dict[str, Any]) -> None:
    """Remove the NaN leaves of `result["learners"]` in place. RLlib 2.60 logs each module's
    `num_trainable_parameters` once, at build, and reports NaN for it in every later
    iteration; a metric with no value this iteration is absent instead."""

    def prune(tree: dict[str, Any]) -> None:
        for key in list(tree):
            value = tree[key]
            if isinstance(value, dict):
                prune(value)
            elif isinstance(value, float) and math.isnan(value):
                del tree[key]

    learners = result.get("learners")
    if isinstance(learners, dict):
        prune(learners)


class DropNaNLearnerStatsCallback(RLlibCallback):
    """`drop_nan_learner_stats` after every training iteration, for runs without ASOR (with
    ASOR, `AsorMetricsCallback` does it)."""

    def on_train_result(self, *, algorithm: Any = None, result: dict, **kwargs: Any) -> None:
        drop_nan_learner_stats(result)


class AsorMetricsCallback(RLlibCallback):
    """Adds `result["asor"]` after every training iteration (and drops the NaN leaves of
    `result["learners"]`, `drop_nan_learner_stats`)."""

    def on_train_result(self, *, algorithm: Any = None, result: dict, **kwargs: Any) -> None:
        drop_nan_learner_stats(result)
        lifted = lift_asor_metrics(result)
        if lifted:
            result["asor"] = lifted
