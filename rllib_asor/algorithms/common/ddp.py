"""Gradients of several modules in the same order on every Learner (DDP).

RLlib 2.60's SAC, CQL and IQL torch Learners compute gradients module by module, one backward
pass per (module, optimizer), iterating `set(loss_per_module.keys())`. The order of a set of
strings depends on the process's hash seed, so two Learner processes walk the modules in
different orders. With `num_learners > 1` every module is DDP-wrapped and each backward pass
all-reduces that module's gradients; ranks that reduce different modules at the same moment
break gloo's collective ("Connection reset by peer", a dead Learner). One module (plain
single-agent SAC) has one order and works; a second module (ASOR's discriminator, a second
policy, ESCP's encoder) exposes it. `SortedModuleGradientsMixin` runs the algorithm's own
`compute_gradients` one module at a time in sorted module-id order.
"""

from __future__ import annotations

from typing import Any

from ray.rllib.core import ALL_MODULES

from rllib_asor import ray_compat as compat


class SortedModuleGradientsMixin:
    """`compute_gradients` of the base Learner, one module at a time, in sorted module-id order.

    The base implementation pops `compat.temp_losses(self)[(module_id, "<optimizer>_loss")]` for the
    modules it is given and asserts none is left, so each call sees only its module's losses.
    """

    def compute_gradients(self, loss_per_module: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        temp = compat.temp_losses(self)
        pending = dict(temp)
        temp.clear()
        grads: dict[str, Any] = {}
        for module_id in sorted(m for m in loss_per_module if m != ALL_MODULES):
            for key in [k for k in pending if k[0] == module_id]:
                temp[key] = pending.pop(key)
            one = {module_id: loss_per_module[module_id]}
            grads.update(super().compute_gradients(one, **kwargs))  # type: ignore[misc]
        if pending:  # the base class asserts the same: every stored loss belongs to a module
            raise RuntimeError(f"losses of modules without a loss entry: {sorted(pending)}")
        return grads
