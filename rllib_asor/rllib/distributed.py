"""ASOR on several Learners (DDP): every Learner runs the same update on the whole train batch.

With `num_learners > 1` each Learner holds a shard of the train batch, and DDP keeps the
discriminator's and proxy's *weights* equal (it all-reduces their gradients). Their other state
(normalisers, archive, auto-λ, the warm-up latch) is updated from batches, outside DDP. The ASOR
piece therefore gathers every Learner's `AsorBatch` and runs `asor_update` on their
concatenation, on every Learner, with the same random stream: the state stays identical on all
ranks by construction (as if one Learner had seen the whole batch), every rank's episodes enter
the archive, and each Learner keeps the reward bonus of its own rows and an equal share of the
discriminator's and proxy's train batches (equal sizes, so every rank takes the same number of
aux gradient steps and DDP's all-reduces line up). docs/algorithm.md, "Many Learners".
"""

from __future__ import annotations

import dataclasses
from typing import Any

import torch
import torch.distributed as dist

from rllib_asor.asor.proxy import ProxyInputs
from rllib_asor.asor.update import AsorBatch


def rank_and_size() -> tuple[int, int]:
    """(rank, world size) of the Learners' process group; (0, 1) when there is none."""
    if dist.is_available() and dist.is_initialized():
        return dist.get_rank(), dist.get_world_size()
    return 0, 1


def _moved(value: Any, device: torch.device | str) -> Any:
    if isinstance(value, torch.Tensor):
        return value.to(device)
    if isinstance(value, AsorBatch | ProxyInputs):
        return dataclasses.replace(
            value,
            **{f.name: _moved(getattr(value, f.name), device) for f in dataclasses.fields(value)},
        )
    return value


def gather_batches(batch: AsorBatch | None, device: torch.device | str) -> list[AsorBatch | None]:
    """Every Learner's batch (None where a Learner has none), in rank order, on `device`.

    A collective: every Learner must call it the same number of times.
    """
    out: list[Any] = [None] * dist.get_world_size()
    dist.all_gather_object(out, None if batch is None else _moved(batch, "cpu"))
    return [None if b is None else _moved(b, device) for b in out]


def even_share(rows: torch.Tensor | None, rank: int, size: int) -> torch.Tensor | None:
    """This rank's block of `rows`: ⌊N / size⌋ rows each (the remainder is left out)."""
    if rows is None:
        return None
    k = rows.shape[0] // size
    return rows[rank * k : (rank + 1) * k]


def even_share_inputs(x: ProxyInputs, rank: int, size: int) -> ProxyInputs:
    """`even_share` of every field of a proxy's inputs."""
    return ProxyInputs(
        *(even_share(getattr(x, f.name), rank, size) for f in dataclasses.fields(ProxyInputs))
    )
