"""ESCP's answers to the ASOR piece (the paper's Algorithm 1): V(s) = min Q(s, tanh μ(s, z),
z̄_task) ranks the replayed states (`escp_state_values`), and r_t += λ·b(s_t) before the TD
targets, as for SAC. ESCP's encoder, RMDM and critics are untouched."""

from __future__ import annotations

from typing import Any

import torch

from rllib_asor.algorithms.common.asor_adapter import AsorAdapter
from rllib_asor.algorithms.escp.module import escp_state_values


class ESCPAsorAdapter(AsorAdapter):
    """ESCP on the fast off-policy path (batches with their windows and task ids)."""

    def state_values(self, module: Any, batch: dict[str, Any]) -> torch.Tensor:
        return escp_state_values(module, batch)
