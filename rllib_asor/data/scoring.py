"""D4RL-style normalised scores of a policy, with the dataset's own reference returns.

Normalised score: 100 * (R - R_random) / (R_expert - R_random) with our own random and expert
datasets' mean episode returns under the same dynamics (the task's manifest).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rllib_asor import ray_compat as compat
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


def policy_module(algo_or_path: Any) -> Any:
    """The default policy's RLModule of an Algorithm, an RLModule, or a checkpoint path
    (an Algorithm checkpoint dir or an RLModule dir)."""
    from ray.rllib.core import DEFAULT_MODULE_ID
    from ray.rllib.core.rl_module.rl_module import RLModule

    if isinstance(algo_or_path, RLModule):
        return algo_or_path
    if isinstance(algo_or_path, str | os.PathLike):
        path = Path(algo_or_path)
        inner = path / "learner_group" / "learner" / "rl_module" / DEFAULT_MODULE_ID
        if inner.is_dir():
            path = inner
        if not path.is_dir():
            raise ValueError(
                f"checkpoint {path} does not exist; expected an Algorithm or RLModule checkpoint"
            )
        return RLModule.from_checkpoint(path.as_posix())
    learner = compat.local_learner(algo_or_path.learner_group)
    if learner is not None:
        return learner.module[DEFAULT_MODULE_ID]
    module = algo_or_path.get_module(DEFAULT_MODULE_ID)
    if module is None:
        raise ValueError("the Algorithm has no local policy module; pass a checkpoint path")
    return module


def rollout_returns(
    module: Any, env_id: str, dynamics: str, episodes: int, seed: int = 0
) -> list[float]:
    """Undiscounted returns of `episodes` deterministic episodes of `module` on the env
    (SAC/CQL squash into [-1, 1]: actions are unsquashed onto the env's bounds)."""
    from rllib_asor.evaluation.rollout import rollout, unsquash

    returns, _ = rollout(
        module, env_id, episodes, seed=seed, env_kwargs={"dynamics": dynamics}, action_fn=unsquash
    )
    return returns


def evaluate(
    algo_or_path: Any,
    manifest: Mapping[str, Any] | str | os.PathLike[str],
    *,
    dynamics: Sequence[str] | None = None,
    episodes: int = 5,
    seed: int = 0,
) -> dict[str, dict[str, float]]:
    """Run the policy under each dynamics (default: the manifest's); return per dynamics
    `return_mean`, `return_std` and `normalized_score`, plus `mean` over dynamics."""
    if not isinstance(manifest, Mapping):
        manifest = read_manifest(manifest)
    module = policy_module(algo_or_path)
    out: dict[str, dict[str, float]] = {}
    for dyn in dynamics or tuple(manifest["datasets"]):
        rets = rollout_returns(module, manifest["env"], dyn, episodes, seed)
        out[dyn] = {
            "return_mean": float(np.mean(rets)),
            "return_std": float(np.std(rets)),
            "normalized_score": normalized_score(
                float(np.mean(rets)), manifest["task"], manifest, dyn
            ),
        }
    if out:
        out["mean"] = {
            k: float(np.mean([v[k] for v in out.values()]))
            for k in ("return_mean", "normalized_score")
        }
    return out
