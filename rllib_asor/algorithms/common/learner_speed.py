"""Same-math speed-ups for RLlib's torch Learners (every Learner class of rllib-asor has them).

- `GradientCheckOnceMixin`: RLlib's nan/inf gradient rule, checked with one host sync per
  minibatch instead of two to three per tensor.
- `FusedAdamMixin`: Adam/AdamW optimizers step with torch's fused kernel (one call for all
  parameters instead of a loop of per-tensor ops; ~4 % of a race PPO update on one CPU core).
- `LeanBatchMixin`: the Learner connector pipeline runs without autograd (its forward passes,
  GAE's critic values and ASOR's ranking, only make numbers for the batch; RLlib builds their
  autograd graphs and drops them), and the per-epoch shuffle gathers torch columns with
  `index_select`, ~4× faster than RLlib's fancy indexing for image-like columns on a CPU, with
  the same permutation.
- `OffPolicynessOnceMixin`: RLlib's off-policyness metric once per update, not per minibatch.
- `SkipIdlePostprocessMixin`: no rebuilding of the gradient dict when no gradient is clipped
  or logged.

`SameMathSpeedMixin` bundles them; mix it in before the algorithm's Learner.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import torch
import tree
from ray.rllib.core.columns import Columns
from ray.rllib.core.learner.learner import Learner
from ray.rllib.policy.sample_batch import SampleBatch

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.common import gpu_sharing

logger = logging.getLogger(__name__)
# Every Learner class here imports this module in the process that builds its Learner group:
# Learners that share a GPU get gloo there instead of NCCL (gpu_sharing.py).
gpu_sharing.install()
# ... and RLlib's connector builds and per-step unbatching in this process get cheap (same results).
compat.fast_rllib()


class GradientCheckOnceMixin:
    """RLlib's rule for nan/inf gradients (set them to zero, with a warning, unless
    `torch_skip_nan_gradients`), checked on their total norm: one host sync per update where
    TorchLearner syncs twice per tensor (~160 times per race PPO minibatch, ~6 % of it)."""

    def build(self) -> None:
        super().build()  # type: ignore[misc]
        self._check_gradients_once = not self.config.torch_skip_nan_gradients  # type: ignore[attr-defined]
        # This Learner's own copy of the config: TorchLearner's per-tensor checks are done here.
        self.config.torch_skip_nan_gradients = True  # type: ignore[attr-defined]

    def apply_gradients(self, gradients_dict: dict[Any, torch.Tensor | None]) -> None:
        if self._check_gradients_once:
            grads = [g for g in gradients_dict.values() if g is not None]
            if grads and not torch.isfinite(torch.nn.utils.get_total_norm(grads)):
                logger.warning("Gradients contain nan/inf values: setting them to zero.")
                gradients_dict = {
                    pid: None if g is None else torch.nan_to_num(g)
                    for pid, g in gradients_dict.items()
                }
        super().apply_gradients(gradients_dict)  # type: ignore[misc]


def fuse_adam(optimizer: torch.optim.Optimizer) -> bool:
    """Switch a fresh (never stepped) Adam/AdamW to torch's fused step where torch supports it
    (floating-point parameters on CPU or CUDA). Returns whether it did."""
    if type(optimizer) not in (torch.optim.Adam, torch.optim.AdamW) or optimizer.state:
        return False
    groups = optimizer.param_groups
    if any(g.get("differentiable") or g.get("foreach") or g.get("fused") is False for g in groups):
        return False  # the user asked for another kernel
    params = [p for g in groups for p in g["params"]]
    if not params or not all(
        p.is_floating_point() and p.device.type in ("cpu", "cuda") for p in params
    ):
        return False
    for g in groups:
        g["fused"], g["foreach"] = True, False
    optimizer.defaults["fused"], optimizer.defaults["foreach"] = True, False
    optimizer._step_supports_amp_scaling = True  # as Adam(fused=True) sets it
    return True


class FusedAdamMixin:
    """Every Adam/AdamW a Learner registers steps with torch's fused kernel (`fuse_adam`)."""

    def register_optimizer(self, *, optimizer: torch.optim.Optimizer, **kwargs: Any) -> None:
        fuse_adam(optimizer)
        super().register_optimizer(optimizer=optimizer, **kwargs)  # type: ignore[misc]


def take_rows(column: Any, index: torch.Tensor) -> Any:
    """`column[index]` along the first axis; torch columns through `index_select` (several times
    faster than fancy indexing for large CPU tensors)."""
    if isinstance(column, torch.Tensor):
        return column.index_select(0, index.to(column.device))
    return column[index.cpu().numpy()]


class IndexSelectShuffleBatch(SampleBatch):
    """A SampleBatch whose `shuffle` takes its permutation as RLlib's does (so the rows come out
    in the same order) and gathers torch columns with `index_select`."""

    def shuffle(self) -> SampleBatch:
        if self.get(SampleBatch.SEQ_LENS) is not None or Columns.INFOS in self:
            return super().shuffle()
        index = torch.from_numpy(np.random.permutation(self.count))
        columns = dict(self)
        # One host-to-device copy of the permutation per device, not one per column (on a GPU
        # each such copy waits for the stream).
        devices = {c.device for c in tree.flatten(columns) if isinstance(c, torch.Tensor)}
        on = {device: index.to(device) for device in devices}

        def take(column: Any) -> Any:
            return take_rows(
                column, on[column.device] if isinstance(column, torch.Tensor) else index
            )

        self.update(tree.map_structure(take, columns))
        self.intercepted_values = {}
        return self


class LeanBatchMixin:
    """Runs the Learner connector pipeline (episodes → train batch) under `torch.no_grad()` and
    gives the batch's flat per-module batches `IndexSelectShuffleBatch`'s shuffle."""

    def _make_batch_if_necessary(self, training_data: Any) -> Any:
        with torch.no_grad():
            batch = super()._make_batch_if_necessary(training_data)  # type: ignore[misc]
        for module_batch in getattr(batch, "policy_batches", {}).values():
            if type(module_batch) is SampleBatch and SampleBatch.SEQ_LENS not in module_batch:
                module_batch.__class__ = IndexSelectShuffleBatch  # adds no state, only the method
        return batch


class OffPolicynessOnceMixin:
    """RLlib's `diff_num_grad_updates_vs_sampler_policy` metric on the first minibatch of each
    update instead of every one: RLlib logs it with window=1, so one minibatch's value is what
    it reports anyway (~1 % of a race PPO update)."""

    _off_policyness_seq_no = -1

    def _compute_off_policyness(self, batch: Any) -> None:
        seq_no = compat.weights_seq_no(self)
        if self._off_policyness_seq_no != seq_no:
            self._off_policyness_seq_no = seq_no
            super()._compute_off_policyness(batch)  # type: ignore[misc]


class SkipIdlePostprocessMixin:
    """RLlib's `postprocess_gradients` rebuilds the gradient dict module by module and optimizer
    by optimizer, hashing every parameter tensor several times (~2 ms of Python per minibatch
    with ASOR's three optimizers), also when it has nothing to do: no module clips
    (`grad_clip`) or logs (`log_gradients`) its gradients and none overrides
    `postprocess_gradients_for_module`. Then the gradients go on as they are (RLlib's rebuilt
    dict holds the same tensors, less the None ones)."""

    _idle_postprocess: tuple[tuple[str, ...], bool] | None = None

    def postprocess_gradients(self, gradients_dict: dict[Any, Any]) -> dict[Any, Any]:
        keys = tuple(self.module.keys())  # type: ignore[attr-defined]
        if self._idle_postprocess is None or self._idle_postprocess[0] != keys:
            configs = [self.config.get_config_for_module(mid) for mid in keys]  # type: ignore[attr-defined]
            idle = type(self).postprocess_gradients_for_module is (
                Learner.postprocess_gradients_for_module
            ) and all(c.grad_clip is None and not c.log_gradients for c in configs)
            self._idle_postprocess = (keys, idle)
        if not self._idle_postprocess[1]:
            return super().postprocess_gradients(gradients_dict)  # type: ignore[misc]
        if any(g is None for g in gradients_dict.values()):
            return {pid: g for pid, g in gradients_dict.items() if g is not None}
        return gradients_dict


class SameMathSpeedMixin(
    FusedAdamMixin,
    LeanBatchMixin,
    OffPolicynessOnceMixin,
    SkipIdlePostprocessMixin,
    GradientCheckOnceMixin,
):
    """All of this module's same-math speed-ups."""
