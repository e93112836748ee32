"""Windows of the last H steps of (s_t, a_{t−1}), the context encoder's input.

ESCP stores each trajectory zero-padded at its front (`utils/replay_memory.py`,
`MemoryArray.complete_traj`: rows start at offset `fix_length`) and samples the H rows ending
at a transition (`MemoryArray.sample_fix_length_sub_trajs`), so a window never reaches into
another episode and its steps before the episode start are zeros (state and last action).
The target's window is the same rows with (s_{t+1}, a_t) (`SAC.sac_update`: `total_state =
next_state`, `total_last_action = action`). At inference ESCP feeds H − 1 zero steps before the
first real one (`Policy.inference_one_step`) and a zero last action at the episode start.

Here the replay buffer is flat (rows of many episodes interleaved), so each row keeps the
serial number of the previous row of its episode (−1 at the episode start) and a window is
gathered by following those links H − 1 times (`window_rows`), never past an episode start or
a row the ring buffer has overwritten. `episode_window` builds the same window from a live
RLlib episode on the env runner.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def window_rows(
    index: np.ndarray,
    prev_serial: np.ndarray,
    history_len: int,
    *,
    capacity: int,
    oldest_serial: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Row positions [n, H] of the windows ending at rows `index` [n] (oldest step first) and
    their validity mask [n, H] (False: before the episode start, or overwritten: pad with 0).

    `prev_serial[pos]` is the serial (global insertion number) of the previous step of the
    row's episode, −1 at an episode start; a serial s lives at position s % capacity while
    s ≥ `oldest_serial`.
    """
    index = np.asarray(index, dtype=np.int64)
    n, h = len(index), int(history_len)
    rows = np.zeros((n, h), dtype=np.int64)
    valid = np.zeros((n, h), dtype=bool)
    rows[:, -1] = index
    valid[:, -1] = True
    for k in range(h - 2, -1, -1):
        prev = prev_serial[rows[:, k + 1]]
        ok = valid[:, k + 1] & (prev >= 0) & (prev >= oldest_serial)
        rows[:, k] = np.where(ok, prev % capacity, 0)
        valid[:, k] = ok
    return rows, valid


def gather_window(
    states: np.ndarray, last_actions: np.ndarray, rows: np.ndarray, valid: np.ndarray
) -> np.ndarray:
    """[n, H, obs_dim + act_dim] float32 windows of (state, last action) at `rows`, zeros where
    not `valid`."""
    out = np.concatenate([states[rows], last_actions[rows]], axis=-1).astype(np.float32)
    out *= valid[..., None]
    return out


def episode_window(episode: Any, history_len: int) -> np.ndarray:
    """The window [H, obs_dim + act_dim] ending at a live RLlib episode's last observation:
    s_{t−H+1..t} and a_{t−H..t−1}, zero-filled before the episode start (the episode needs a
    lookback buffer of ≥ H − 1 steps across chunk boundaries: `episode_lookback_horizon`)."""
    h = int(history_len)
    obs = np.asarray(episode.get_observations(slice(-h, None), fill=0.0), dtype=np.float32)
    acts = np.asarray(episode.get_actions(slice(-h, None), fill=0.0), dtype=np.float32)
    return np.concatenate([obs.reshape(h, -1), acts.reshape(h, -1)], axis=-1)
