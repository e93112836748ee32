"""ASOR on MAPLE: MAPLE's Learner plus the ASOR piece.

MAPLE's batches come from `MAPLE.training_step` through `learner_group.update(batch=...)`,
bypassing the Learner connector, so the Learner applies the piece to each batch before the
SAC step (`AsorLearnerMixin._update`). MAPLE's adapter (`algorithms/maple/asor_adapter.py`)
says what differs: the real transitions (`real_*` columns) are ranked by V(s) = min Q(s, π(s))
with their GRU contexts and by the visitation proxy, and every segment step (real and model)
gets λ·b(s) in the `asor_bonus` column, which MAPLE's loss adds to the rewards. MAPLE itself
(`rllib_asor.algorithms.maple`) knows nothing of ASOR.
"""

from __future__ import annotations

from rllib_asor.algorithms.maple.asor_adapter import MapleAsorAdapter
from rllib_asor.algorithms.maple.learner import MapleTorchLearner
from rllib_asor.rllib.learners import AsorLearnerMixin


class AsorMapleTorchLearner(AsorLearnerMixin, MapleTorchLearner):
    """MAPLE's Learner with ASOR; the discriminator and the proxy train on the real states'
    partition in the same update. Offline: λ's timestep is the number of real rows ranked so
    far (not checkpointed)."""

    asor_adapter = MapleAsorAdapter()
