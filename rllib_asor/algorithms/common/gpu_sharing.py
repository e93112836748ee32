"""Several Learners on one GPU: their process group uses gloo instead of NCCL.

RLlib 2.60 lets Ray Train choose the Learners' `torch.distributed` backend, and Ray Train picks
NCCL whenever a Learner holds any GPU. NCCL refuses two ranks on one device ("Duplicate GPU
detected"), so `num_learners=2, num_gpus_per_learner=0.5` cannot start (RLlib's own
fractional-GPU example says to expect that NCCL error). `install()` keeps RLlib's backend and
changes one decision: with a fraction of a GPU per Learner the backend is gloo, which reduces
CUDA tensors too (through the host). Whole GPUs per Learner keep NCCL.
"""

from __future__ import annotations

from typing import Any

from rllib_asor import ray_compat as compat


def shares_a_gpu(resources_per_learner: dict[str, Any]) -> bool:
    """Whether Learners with these resources may sit on one GPU (a fraction of a GPU each)."""
    gpus = float(resources_per_learner.get("GPU", 0) or 0)
    return 0.0 < gpus < 1.0


def install() -> None:
    """Make RLlib's Learner groups use gloo when their Learners share a GPU (idempotent;
    call on the driver before the algorithm is built)."""
    original = compat.backend_config_factory()
    if getattr(original, "shares_gpus_with_gloo", False):
        return

    def backend_config(learner_class: type) -> Any:
        config = original(learner_class)
        rllib_backend = config.backend_cls

        class SharedGpuBackend(rllib_backend):  # type: ignore[misc, valid-type]
            def on_start(self, worker_group: Any, backend_config: Any) -> None:
                if backend_config.backend is None and shares_a_gpu(
                    worker_group.get_resources_per_worker()
                ):
                    backend_config.backend = "gloo"
                super().on_start(worker_group, backend_config)

        class SharedGpuConfig(type(config)):  # type: ignore[misc]
            @property
            def backend_cls(self) -> type:
                return SharedGpuBackend

        return SharedGpuConfig()

    backend_config.shares_gpus_with_gloo = True  # type: ignore[attr-defined]
    compat.set_backend_config_factory(backend_config)
