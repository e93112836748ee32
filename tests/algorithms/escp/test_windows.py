"""Windows gathered from flat replay rows: never across an episode start, first steps padded
(ESCP utils/replay_memory.py MemoryArray), and equal to the env runner's live window."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from ray.rllib.core.columns import Columns
from ray.rllib.env.single_agent_episode import SingleAgentEpisode

from rllib_asor.algorithms.escp.replay import (
    DYNAMICS_ID,
    NEXT_WINDOW,
    WINDOW,
    EscpReplayBuffer,
)
from rllib_asor.algorithms.escp.windows import episode_window, window_rows

OBS = gym.spaces.Box(-1e3, 1e3, (3,), np.float32)
ACT = gym.spaces.Box(-1, 1, (2,), np.float32)
H = 4


def test_window_rows_stop_at_episode_start_and_overwritten_rows() -> None:
    # serials 0..5: episode A = 0,1,2 ; episode B = 3,4 ; episode A' (new) = 5
    prev = np.array([-1, 0, 1, -1, 3, -1])
    rows, valid = window_rows(np.array([2, 4, 5]), prev, 3, capacity=6)
    assert rows.tolist() == [[0, 1, 2], [0, 3, 4], [0, 0, 5]]
    assert valid.tolist() == [[True, True, True], [False, True, True], [False, False, True]]
    rows, valid = window_rows(np.array([2]), prev, 3, capacity=6, oldest_serial=1)
    assert valid.tolist() == [[False, True, True]]  # serial 0 was overwritten


def _trajectory(seed: int, length: int, task: int) -> list[tuple]:
    rng = np.random.default_rng(seed)
    obs = rng.normal(size=(length + 1, 3)).astype(np.float32) + 5.0  # never zero
    act = rng.uniform(-1, 1, size=(length, 2)).astype(np.float32)
    return obs, act, task


def _chunks(obs: np.ndarray, act: np.ndarray, task: int, cuts: list[int]) -> list:
    """One episode, cut into chunks as the env runner does (lookback H)."""
    ep = SingleAgentEpisode(observation_space=OBS, action_space=ACT)
    ep.add_env_reset(observation=obs[0], infos={"dynamics_id": task})
    out, t = [], 0
    for end in [*cuts, len(act)]:
        while t < end:
            ep.add_env_step(
                observation=obs[t + 1],
                action=act[t],
                reward=float(t),
                infos={"dynamics_id": task},
                terminated=t + 1 == len(act),
            )
            t += 1
        out.append(ep)
        if not ep.is_done:
            ep = ep.cut(len_lookback_buffer=H)
    return out


def _expected(obs: np.ndarray, act: np.ndarray, t: int) -> tuple[np.ndarray, np.ndarray]:
    """ESCP's window for step t: rows t-H+1..t of (s, a_prev) and of (s', a), zeros before 0."""
    win = np.zeros((H, 5), np.float32)
    nxt = np.zeros((H, 5), np.float32)
    for j, k in enumerate(range(t - H + 1, t + 1)):
        if k < 0:
            continue
        win[j] = np.concatenate([obs[k], act[k - 1] if k > 0 else np.zeros(2)])
        if k < len(act):
            nxt[j] = np.concatenate([obs[k + 1], act[k]])
    return win, nxt


def test_replay_windows_equal_escp_windows_with_interleaved_chunks() -> None:
    a = _trajectory(0, 11, task=7)
    b = _trajectory(1, 9, task=3)
    ca, cb = _chunks(*a, cuts=[2, 6]), _chunks(*b, cuts=[5])
    buf = EscpReplayBuffer(capacity=100, history_len=H, seed=0)
    buf.add([ca[0], cb[0]])  # chunks of both episodes interleave in the flat rows
    buf.add([ca[1]])
    buf.add([cb[1], ca[2]])
    assert len(buf) == 20
    cols = buf.columns_at(np.arange(20))
    # Map each row back to (episode, step) through its reward (= step) and task id.
    for i in range(20):
        t = int(cols[Columns.REWARDS][i])
        obs, act, task = a if cols[DYNAMICS_ID][i] == 7 else b
        win, nxt = _expected(obs, act, t)
        np.testing.assert_array_equal(cols[WINDOW][i], win)
        np.testing.assert_array_equal(cols[NEXT_WINDOW][i], nxt)
        np.testing.assert_array_equal(cols[Columns.OBS][i], obs[t])


def test_live_window_equals_replay_window() -> None:
    obs, act, task = _trajectory(2, 9, task=1)
    chunks = _chunks(obs, act, task, cuts=[3, 5])
    for chunk in chunks[1:]:  # the acting window after t steps of a continued chunk
        t = chunk.t_started + len(chunk)
        win, _ = _expected(obs, act, t)
        np.testing.assert_array_equal(episode_window(chunk, H), win)
    fresh = SingleAgentEpisode(observation_space=OBS, action_space=ACT)
    fresh.add_env_reset(observation=obs[0], infos={})
    np.testing.assert_array_equal(episode_window(fresh, H), _expected(obs, act, 0)[0])


def test_ring_overwrite_pads_instead_of_reading_newer_rows() -> None:
    obs, act, task = _trajectory(3, 10, task=2)
    buf = EscpReplayBuffer(capacity=6, history_len=H, seed=0)
    chunks = _chunks(obs, act, task, cuts=[5])
    buf.add([chunks[0]])
    buf.add([chunks[1]])  # rows of steps 0..3 overwritten by steps 6..9
    cols = buf.columns_at(np.arange(6))
    for i in range(6):
        t = int(cols[Columns.REWARDS][i])
        win, _ = _expected(obs, act, t)
        lost = max(0, H - 1 - (t - 4))  # steps 0..3 are gone
        win[: min(lost, H)] = 0.0
        np.testing.assert_array_equal(cols[WINDOW][i], win)


def test_missing_dynamics_id_is_a_clear_error() -> None:
    ep = SingleAgentEpisode(observation_space=OBS, action_space=ACT)
    ep.add_env_reset(observation=np.ones(3, np.float32), infos={})
    ep.add_env_step(
        observation=np.ones(3, np.float32),
        action=np.zeros(2, np.float32),
        reward=0.0,
        infos={"x": 1},
    )
    with pytest.raises(ValueError, match=r"int `dynamics_id` in the info dict.*keys \['x'\]"):
        EscpReplayBuffer(capacity=10, history_len=H).add([ep])


def test_state_round_trip_keeps_episode_links() -> None:
    obs, act, task = _trajectory(4, 8, task=5)
    c = _chunks(obs, act, task, cuts=[4])
    buf = EscpReplayBuffer(capacity=50, history_len=H, seed=1)
    buf.add([c[0]])
    other = EscpReplayBuffer(capacity=50, history_len=H, seed=9)
    other.set_state(buf.get_state())
    other.add([c[1]])
    buf.add([c[1]])
    for k, v in buf.columns_at(np.arange(8)).items():
        np.testing.assert_array_equal(other.columns_at(np.arange(8))[k], v)
