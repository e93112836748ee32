"""OSI's replay buffer: ESCP's (windows of (s, a_{t−1}), task ids) plus each step's true
dynamics parameters (`info["dynamics_params"]`), which π, the critics and OSI's loss read."""

from __future__ import annotations

from typing import Any

import numpy as np

from rllib_asor.algorithms.escp.replay import EscpReplayBuffer

PARAMS = "osi_params"
"""Batch column: [B, param_dim] true dynamics parameters of the step."""

NO_PARAMS = (
    "OSI needs the dynamics parameters of every step: the env must put a float vector "
    "`dynamics_params` in the info dict of reset() and step() (rllib_asor/*Shift-v0 do); {detail}"
)


def dynamics_params(infos: list[dict[str, Any]]) -> np.ndarray:
    """`info["dynamics_params"]` of each info dict as a [N, P] float32 array; ValueError
    naming what is missing."""
    rows = []
    for info in infos:
        value = info.get("dynamics_params") if isinstance(info, dict) else None
        if value is None:
            keys = sorted(info) if isinstance(info, dict) else type(info).__name__
            raise ValueError(NO_PARAMS.format(detail=f"got an info with keys {keys}"))
        rows.append(np.asarray(value, dtype=np.float32).reshape(-1))
    return np.stack(rows) if rows else np.zeros((0, 0), dtype=np.float32)


class OsiReplayBuffer(EscpReplayBuffer):
    """ESCP's buffer with a `PARAMS` column (same rows, same order)."""

    def add(self, episodes: Any) -> None:
        if not isinstance(episodes, list):
            episodes = [episodes]
        params = [
            dynamics_params(ep.get_infos(slice(1, len(ep) + 1))) for ep in episodes if len(ep) > 0
        ]
        self._pending_params = np.concatenate(params) if params else None
        try:
            super().add(episodes)
        finally:
            self._pending_params = None

    def _allocate(self, first: dict[str, np.ndarray]) -> None:
        super()._allocate(self._with_params(first))

    def _write(self, new: dict[str, np.ndarray]) -> None:
        super()._write(self._with_params(new))

    def _with_params(self, cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        pending = getattr(self, "_pending_params", None)
        if PARAMS in cols or pending is None:
            return cols
        return {**cols, PARAMS: pending}

    def columns_at(self, idx: np.ndarray) -> dict[str, np.ndarray]:
        return {**super().columns_at(idx), PARAMS: self._cols[PARAMS][idx]}
