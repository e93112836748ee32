"""ESCP's replay buffer: the project's flat buffer plus what ESCP's windows need.

`FlatReplayBuffer` (rllib_asor/algorithms/sac/replay.py) keeps transitions as flat rows; ESCP
also needs, per row, the previous action a_{t−1}, the task id (`info["dynamics_id"]` of the
step) and a link to the previous row of the same episode, so that `sample()` can return the
H-step windows of (s, a_{t−1}) ending at each sampled transition and the target's windows of
(s′, a) (windows.py; ESCP `MemoryArray.sample_fix_length_sub_trajs`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from ray.rllib.core.columns import Columns

from rllib_asor.algorithms.escp.windows import gather_window, window_rows
from rllib_asor.algorithms.sac.replay import FlatReplayBuffer, FlatTransitions

WINDOW = "escp_window"
"""Batch column: [B, H, obs_dim + act_dim] windows of (s, a_{t−1}) ending at s_t."""
NEXT_WINDOW = "escp_next_window"
"""Batch column: the same rows with (s′, a): the window ending at s_{t+1}."""
DYNAMICS_ID = "dynamics_id"
"""Batch column: `info["dynamics_id"]` of the step (ESCP's task id)."""
PREV_ACTIONS = "escp_prev_actions"
PREV_SERIAL = "escp_prev_serial"

NO_DYNAMICS_ID = (
    "ESCP needs the task of every step: the env must put an int `dynamics_id` in the info dict "
    "of reset() and step() (one id per training task, e.g. rllib_asor/*Shift-v0 with "
    "env_config num_tasks=40 does); {detail}"
)


def dynamics_ids(infos: list[dict[str, Any]]) -> np.ndarray:
    """The int `dynamics_id` of each info dict; ValueError naming what is missing."""
    out = np.empty(len(infos), dtype=np.int64)
    for i, info in enumerate(infos):
        value = info.get("dynamics_id") if isinstance(info, dict) else None
        if value is None:
            keys = sorted(info) if isinstance(info, dict) else type(info).__name__
            raise ValueError(NO_DYNAMICS_ID.format(detail=f"got an info with keys {keys}"))
        try:
            out[i] = int(value)
        except (TypeError, ValueError):
            raise ValueError(
                NO_DYNAMICS_ID.format(detail=f"got dynamics_id={value!r}, not an int")
            ) from None
    return out


class EscpReplayBuffer(FlatReplayBuffer):
    """Uniform replay of transitions whose samples carry ESCP's windows and task ids.

    Args:
        capacity: rows kept (a ring).
        history_len: H, the window length (ESCP's `rnn_fix_length`, 16).
        seed: sampling RNG seed.
    """

    def __init__(
        self, capacity: int = 1_000_000, *, history_len: int = 16, seed: int | None = None, **kw
    ):
        super().__init__(capacity=capacity, seed=seed, **kw)
        self.history_len = int(history_len)
        self._last_serial: dict[str, int] = {}  # episode id -> serial of its latest row

    def add(self, episodes: Any) -> None:
        """Append every step of the given episode chunks (in order; chunks of one episode
        are linked through their ids)."""
        if not isinstance(episodes, list):
            episodes = [episodes]
        parts, serial = [], self._added
        for ep in episodes:
            n = len(ep)
            if n == 0:
                continue
            if not hasattr(ep, "get_observations") or hasattr(ep, "agent_episodes"):
                raise ValueError("ESCP's replay buffer stores single-agent episodes only")
            obs = np.asarray(ep.get_observations(slice(0, n + 1)), dtype=np.float32)
            actions = np.asarray(ep.get_actions(slice(0, n)), dtype=np.float32)
            ids = dynamics_ids(ep.get_infos(slice(1, n + 1)))  # the info of each step
            prev_serial = serial - 1 + np.arange(n, dtype=np.int64)
            prev_actions = np.empty_like(actions)
            prev_actions[1:] = actions[:-1]
            last = self._last_serial.pop(ep.id_, None) if ep.t_started > 0 else None
            if last is None:  # the episode starts here (or its start is gone)
                prev_serial[0] = -1
                prev_actions[0] = 0.0
            else:
                prev_serial[0] = last
                prev_actions[0] = np.asarray(
                    ep.get_actions(-1, neg_index_as_lookback=True, fill=0.0), dtype=np.float32
                )
            done = np.zeros(n, dtype=bool)
            trunc = np.zeros(n, dtype=bool)
            done[-1], trunc[-1] = bool(ep.is_terminated), bool(ep.is_truncated)
            serial += n
            if not ep.is_done:
                self._last_serial[ep.id_] = serial - 1
            parts.append(
                {
                    Columns.OBS: obs[:-1],
                    Columns.ACTIONS: actions,
                    Columns.REWARDS: np.asarray(ep.get_rewards(slice(0, n)), dtype=np.float32),
                    Columns.NEXT_OBS: obs[1:],
                    Columns.TERMINATEDS: done,
                    Columns.TRUNCATEDS: trunc,
                    PREV_ACTIONS: prev_actions,
                    DYNAMICS_ID: ids,
                    PREV_SERIAL: prev_serial,
                }
            )
        if not parts:
            return
        new = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
        if self._cols is None:
            self._allocate(new)
        self._write(new)
        self._forget_stale_episodes()
        self.metrics.log_value("num_env_steps_added", len(new[Columns.REWARDS]), reduce="sum")

    def _write(self, new: dict[str, np.ndarray]) -> None:
        """Row with serial s goes to position s % capacity (windows rely on it)."""
        n = len(new[Columns.REWARDS])
        serials = self._added + np.arange(n, dtype=np.int64)
        if n > self.capacity:
            new = {k: v[-self.capacity :] for k, v in new.items()}
            serials = serials[-self.capacity :]
        pos = serials % self.capacity
        for k, v in new.items():
            self._cols[k][pos] = v
        self._added += n
        self._pos = int(self._added % self.capacity)
        self._size = min(self._size + n, self.capacity)

    def _forget_stale_episodes(self) -> None:
        oldest = self._added - self._size
        if len(self._last_serial) > 4096:  # abandoned episodes (runner restarts)
            self._last_serial = {k: s for k, s in self._last_serial.items() if s >= oldest}

    def sample(
        self,
        num_items: int | None = None,
        *,
        batch_size_B: int | None = None,
        n_step: Any = 1,
        **kwargs: Any,
    ) -> list[FlatTransitions]:
        """`num_items` transitions drawn uniformly with replacement, with their windows."""
        if n_step not in (None, 1):
            raise ValueError(f"ESCP's replay buffer supports n_step=1 only, got {n_step!r}")
        if self._size == 0:
            raise ValueError("EscpReplayBuffer.sample() on an empty buffer")
        n = int(num_items or batch_size_B or self.batch_size_B)
        idx = self.rng.integers(0, self._size, size=n)
        self.sampled_timesteps += n
        self.metrics.log_value("num_env_steps_sampled", n, reduce="sum")
        return [FlatTransitions(self.columns_at(idx))]

    def columns_at(self, idx: np.ndarray) -> dict[str, np.ndarray]:
        """The train-batch columns of rows `idx`: SAC's six plus windows and task ids."""
        c = self._cols
        rows, valid = window_rows(
            idx,
            c[PREV_SERIAL],
            self.history_len,
            capacity=self.capacity,
            oldest_serial=self._added - self._size,
        )
        return {
            Columns.OBS: c[Columns.OBS][idx],
            Columns.ACTIONS: c[Columns.ACTIONS][idx],
            Columns.REWARDS: c[Columns.REWARDS][idx],
            Columns.NEXT_OBS: c[Columns.NEXT_OBS][idx],
            Columns.TERMINATEDS: c[Columns.TERMINATEDS][idx],
            Columns.TRUNCATEDS: c[Columns.TRUNCATEDS][idx],
            WINDOW: gather_window(c[Columns.OBS], c[PREV_ACTIONS], rows, valid),
            NEXT_WINDOW: gather_window(c[Columns.NEXT_OBS], c[Columns.ACTIONS], rows, valid),
            DYNAMICS_ID: c[DYNAMICS_ID][idx],
        }

    def get_state(self) -> dict[str, Any]:
        state = super().get_state()
        state["last_serial"] = dict(self._last_serial)
        state["history_len"] = self.history_len
        return state

    def set_state(self, state: dict[str, Any]) -> None:
        super().set_state(state)
        self._last_serial = dict(state.get("last_serial", {}))
        self.history_len = int(state.get("history_len", self.history_len))
