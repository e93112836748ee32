"""Learners that share a GPU get gloo instead of NCCL (rllib_asor/algorithms/common/gpu_sharing.py).

NCCL refuses two ranks on one device, so RLlib's `num_learners=2, num_gpus_per_learner=0.5`
fails with NCCL; the GPU run of that setting is in tests/test_gpu_training.py. Here: the rule,
and that RLlib's Learner groups use the backend that applies it once any of our Learners is
imported (two CPU Learners train with it: tests/cluster/test_many_learners.py).
"""

from __future__ import annotations

import pytest

from rllib_asor.algorithms.common.gpu_sharing import install, shares_a_gpu


@pytest.mark.parametrize(
    ("resources", "shared"),
    [({"CPU": 0, "GPU": 0.5}, True), ({"GPU": 0.25}, True), ({"GPU": 1}, False),
     ({"GPU": 2}, False), ({"CPU": 1, "GPU": 0}, False), ({"CPU": 1}, False)],
)
def test_a_fraction_of_a_gpu_per_learner_means_shared_gpus(resources, shared) -> None:
    assert shares_a_gpu(resources) is shared


def test_importing_our_learners_gives_rllib_the_gpu_sharing_backend() -> None:
    from ray.rllib.algorithms.ppo.torch.ppo_torch_learner import PPOTorchLearner
    from ray.rllib.core.learner import learner_group

    import rllib_asor.rllib.learners  # noqa: F401  (imports the Learners' common module)

    install()  # idempotent: a second call wraps nothing twice
    config = learner_group._get_backend_config(PPOTorchLearner)
    backend = config.backend_cls
    assert backend.__name__ == "SharedGpuBackend"
    assert backend.__mro__[1].__name__ == "_RLlibTorchBackend"  # RLlib's own, kept
    assert backend.share_cuda_visible_devices is False
    assert config.backend is None  # decided when the group starts, from its resources
