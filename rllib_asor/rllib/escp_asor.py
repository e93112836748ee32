"""ASOR on ESCP (the paper's Algorithm 1): ESCP's Learner plus the ASOR piece.

The piece runs on each Learner call's batch, built from ESCP's replay rows (windows and task
ids included), before the gradient steps: V(s) = min Q(s, tanh μ(s, z), z̄_task) ranks the
states (`escp_state_values`), the discriminator is trained, and r_t += λ·b(s_t) before the TD
targets, as for SAC (`AsorSACTorchLearner`). ESCP's own encoder, RMDM and critics are
untouched (`rllib_asor.algorithms.escp`, which knows nothing of ASOR).
"""

from __future__ import annotations

from ray.rllib.algorithms.sac.torch.sac_torch_learner import SACTorchLearner

from rllib_asor.algorithms.escp.learner import EscpLearnerMixin
from rllib_asor.algorithms.escp.module import escp_state_values
from rllib_asor.rllib.learners import FastSoftQAsorMixin


class AsorESCPTorchLearner(FastSoftQAsorMixin, EscpLearnerMixin, SACTorchLearner):
    """ESCP's Learner with ASOR's reward augmentation on the fast path's batches."""

    asor_value_fn = staticmethod(escp_state_values)
