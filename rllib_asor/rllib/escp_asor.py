"""ASOR on ESCP (the paper's Algorithm 1): ESCP's Learner plus the ASOR piece.

The piece runs on each Learner call's batch, built from ESCP's replay rows (windows and task
ids included), before the gradient steps; ESCP's adapter (`algorithms/escp/asor_adapter.py`)
says V(s) = min Q(s, tanh μ(s, z), z̄_task) ranks the states and r_t += λ·b(s_t) goes in
before the TD targets, as for SAC (`AsorSACTorchLearner`). ESCP's own encoder, RMDM and
critics are untouched (`rllib_asor.algorithms.escp`, which knows nothing of ASOR).
"""

from __future__ import annotations

from rllib_asor.algorithms.escp.asor_adapter import ESCPAsorAdapter
from rllib_asor.algorithms.escp.learner import EscpTorchLearner
from rllib_asor.rllib.learners import FastSoftQAsorMixin


class AsorESCPTorchLearner(FastSoftQAsorMixin, EscpTorchLearner):
    """ESCP's Learner (a subclass of it) with ASOR's reward augmentation on the fast path's
    batches."""

    asor_adapter = ESCPAsorAdapter()
