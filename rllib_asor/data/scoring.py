"""D4RL-style normalised scores of a policy, with the dataset's own reference returns.

Normalised score: 100 * (R - R_random) / (R_expert - R_random) with our own random and expert
datasets' mean episode returns under the same dynamics (the task's manifest).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from rllib_asor.data.format import read_manifest


def normalized_score(
    return_: float,
    task: str,
    manifest: Mapping[str, Any] | str | os.PathLike[str],
    dynamics: str = "original",
) -> float:
    """D4RL score 100·(R − R_random)/(R_expert − R_random), with the manifest's own random and
    expert mean returns under `dynamics`; `manifest` is a dict or a task directory."""
    if not isinstance(manifest, Mapping):
        manifest = read_manifest(manifest)
    if manifest.get("task") != task:
        raise ValueError(f"manifest is for task {manifest.get('task')!r}, not {task!r}")
    refs = manifest["reference_returns"].get(dynamics)
    if not refs or "random" not in refs or "expert" not in refs:
        raise ValueError(
            f"no random and expert reference returns for dynamics {dynamics!r} of task {task!r}"
        )
    lo, hi = float(refs["random"]), float(refs["expert"])
    if math.isclose(hi, lo):
        raise ValueError(
            f"expert and random returns of {task}/{dynamics} are equal ({lo}); cannot normalise"
        )
    return 100.0 * (float(return_) - lo) / (hi - lo)


def evaluate(
    algo_or_path: Any,
    manifest: Mapping[str, Any] | str | os.PathLike[str],
    *,
    dynamics: Sequence[str] | None = None,
    episodes: int = 5,
    seed: int = 0,
) -> dict[str, dict[str, float]]:
    """Run the policy (an Algorithm, an RLModule or a checkpoint path: its deterministic
    action, unsquashed onto the env's bounds as for SAC/CQL) under each dynamics (default: the
    manifest's); return per dynamics `return_mean`, `return_std` and `normalized_score`, plus
    `mean` over dynamics."""
    from rllib_asor.evaluation.rollout import module_actor, policy_module

    return score_dynamics(
        module_actor(policy_module(algo_or_path)), manifest, dynamics=dynamics,
        episodes=episodes, seed=seed,
    )  # fmt: skip


def score_dynamics(
    actor: Any,
    manifest: Mapping[str, Any] | str | os.PathLike[str],
    *,
    dynamics: Sequence[str] | None = None,
    episodes: int = 5,
    seed: int = 0,
    unscored_ok: bool = False,
) -> dict[str, dict[str, float]]:
    """`evaluate` for any `rllib_asor.evaluation.rollout` actor (MAPLE's GRU policy, ...):
    `episodes` episodes (reset seeds seed, seed + 1, ...) under each dynamics, actions
    unsquashed onto the env's bounds. With `unscored_ok`, a dynamics without random/expert
    reference returns gets a NaN score instead of a ValueError."""
    from rllib_asor.evaluation.rollout import rollout, unsquash

    if not isinstance(manifest, Mapping):
        manifest = read_manifest(manifest)
    out: dict[str, dict[str, float]] = {}
    for dyn in dynamics or tuple(manifest["datasets"]):
        rets = rollout(
            actor, manifest["env"], episodes, seed=seed, env_kwargs={"dynamics": dyn},
            action_fn=unsquash,
        ).returns  # fmt: skip
        try:
            score = normalized_score(float(np.mean(rets)), manifest["task"], manifest, dyn)
        except ValueError:
            if not unscored_ok:
                raise
            score = float("nan")
        out[dyn] = {
            "return_mean": float(np.mean(rets)),
            "return_std": float(np.std(rets)),
            "normalized_score": score,
        }
    if out:
        out["mean"] = {
            k: float(np.mean([v[k] for v in out.values()]))
            for k in ("return_mean", "normalized_score")
        }
    return out
