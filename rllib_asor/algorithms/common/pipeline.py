"""Placing our pieces in RLlib's Learner connector pipelines, by what they must follow."""

from __future__ import annotations

from typing import Any


def insert_beside(pipeline: Any, anchor: type, piece: Any, *, before: bool) -> None:
    """Insert `piece` right before (or after) the first piece that is an `anchor`, subclasses
    included. RLlib's `insert_before`/`insert_after` match the exact class and, when none
    matches, insert next to the pipeline's last piece without a word; here that is an error."""
    found = next((c for c in pipeline.connectors if isinstance(c, anchor)), None)
    where = "before" if before else "after"
    if found is None:
        raise ValueError(
            f"{type(piece).__name__} must go {where} {anchor.__name__} in the Learner "
            "connector pipeline, and this pipeline has none (keep "
            "add_default_connectors_to_learner_pipeline=True)"
        )
    (pipeline.insert_before if before else pipeline.insert_after)(type(found), piece)
