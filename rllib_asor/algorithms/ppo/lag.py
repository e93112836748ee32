"""Overlapped PPO's policy lag, corrected: decoupled PPO (Hilton et al. 2021, "Batch size-
invariance for policy optimization", its decoupled objective with a proximal policy).

`OverlappedPPO` trains the weights θ_k on batch k while the runners sample batch k+1 with the
weights they hold, one update older (the behaviour policy μ). RLlib's PPO takes its clipped
ratio against μ's log-probabilities, so with a lag its trust region sits around μ instead of
around θ_k, and rows whose ratio already starts beyond the clip give no gradient.
`ProximalCorrection`, a Learner connector piece right after GAE, runs the current policy π_k once
per update on the batch (no gradient) and

- replaces the batch's action log-probabilities and distribution inputs by π_k's, so that PPO's
  ratio r = π_θ/π_k and its KL term are taken against the weights being trained (the proximal
  policy), and
- multiplies each row's (standardised) advantage by w = min(π_k(a|s) / μ(a|s), ρ̄), the
  importance weight from the behaviour to the proximal policy, truncated as V-trace truncates
  (ρ̄ = `lag_weight_clip`, default 1).

Because w ≥ 0, w · min(r·A, clip(r)·A) = min(r·wA, clip(r)·wA): PPO's loss is unchanged and the
piece works with every PPO Learner here. Without lag (π_k = μ) w = 1 and nothing changes. The
value targets stay GAE's on the lagged rows (one iteration of lag). Switched on with the overlap
(`learner_config_dict: {overlap_sampling: true}`); `lag_correction: false` turns it off.
"""

from __future__ import annotations

import math
from typing import Any

import torch
from ray.rllib.connectors.connector_v2 import ConnectorV2
from ray.rllib.core.columns import Columns
from ray.rllib.evaluation.postprocessing import Postprocessing

CORRECTION_KEY = "lag_correction"
"""`learner_config_dict` key: False turns the correction off (it is on with the overlap)."""
WEIGHT_CLIP_KEY = "lag_weight_clip"
"""`learner_config_dict` key: ρ̄, the importance weights' upper bound (default 1.0)."""


def lag_weights(
    proximal_logp: torch.Tensor, behaviour_logp: torch.Tensor, clip: float
) -> torch.Tensor:
    """w = min(exp(log π_k − log μ), ρ̄) per row."""
    return torch.clamp(torch.exp(proximal_logp - behaviour_logp), max=clip)


class ProximalCorrection(ConnectorV2):
    """After GAE: the current policy's log-probabilities in place of the behaviour policy's, the
    advantages weighted by the truncated importance weight (module docstring). Logs per module
    ``lag/logp_gap`` (mean |log π_k − log μ|, the lag's size), ``lag/weight_mean`` and
    ``lag/truncated_fraction``."""

    def __init__(self, weight_clip: float = 1.0, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        if not weight_clip > 0:
            raise ValueError(f"{WEIGHT_CLIP_KEY}: {weight_clip} is invalid; allowed a number > 0")
        self.weight_clip = float(weight_clip)

    def __call__(
        self, *, rl_module: Any, batch: dict[str, Any], episodes: Any = None, **kwargs: Any
    ) -> Any:
        metrics = kwargs.get("metrics")
        for mid, rows in batch.items():
            if Postprocessing.ADVANTAGES not in rows or Columns.ACTION_LOGP not in rows:
                continue  # not a PPO policy's rows (ASOR's modules, a module not trained)
            module = rl_module[mid].unwrapped()
            with torch.no_grad():
                out = module.forward_train(rows)
                dist = module.get_train_action_dist_cls().from_logits(
                    out[Columns.ACTION_DIST_INPUTS]
                )
                proximal = dist.logp(rows[Columns.ACTIONS]).to(rows[Columns.ACTION_LOGP].dtype)
            behaviour = rows[Columns.ACTION_LOGP]
            w = lag_weights(proximal, behaviour, self.weight_clip)
            rows[Postprocessing.ADVANTAGES] = rows[Postprocessing.ADVANTAGES] * w
            rows[Columns.ACTION_LOGP] = proximal
            rows[Columns.ACTION_DIST_INPUTS] = out[Columns.ACTION_DIST_INPUTS].detach()
            if metrics is not None:
                mask = rows.get(Columns.LOSS_MASK)
                gap, w_valid = proximal - behaviour, w
                if mask is not None:
                    gap, w_valid = gap[mask], w[mask]
                metrics.log_dict(
                    {
                        "lag/logp_gap": gap.abs().mean(),
                        "lag/weight_mean": w_valid.mean(),
                        "lag/truncated_fraction": (gap > math.log(self.weight_clip)).float().mean(),
                    },
                    key=mid,
                    window=1,
                )
        return batch


def add_correction(learner: Any, weight_clip: float = 1.0) -> None:
    """Insert `ProximalCorrection` right after GAE in `learner`'s connector pipeline (once)."""
    from ray.rllib.connectors.learner import GeneralAdvantageEstimation

    from rllib_asor import ray_compat as compat
    from rllib_asor.algorithms.common.pipeline import insert_beside

    pipeline = compat.learner_connector(learner)
    if pipeline is None:
        raise ValueError(
            f"{CORRECTION_KEY} needs the Learner connector pipeline; set "
            "num_aggregator_actors_per_learner=0 (or lag_correction: false)"
        )
    if any(isinstance(c, ProximalCorrection) for c in pipeline.connectors):
        return
    insert_beside(
        pipeline, GeneralAdvantageEstimation, ProximalCorrection(weight_clip), before=False
    )
