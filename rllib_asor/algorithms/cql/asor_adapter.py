"""CQL's answers to the ASOR piece: as SAC's (soft-Q V(s), the bonus before the TD target),
but dataset batches come through Ray Data's `OfflinePreLearner`, where Learner-connector
pieces never run, so the Learner applies the piece to each batch; λ's timestep is the number
of dataset rows ranked so far (offline runs sample no env steps)."""

from __future__ import annotations

from rllib_asor.algorithms.sac.asor_adapter import SACAsorAdapter


class CQLAsorAdapter(SACAsorAdapter):
    """CQL (offline)."""

    in_pipeline = False
