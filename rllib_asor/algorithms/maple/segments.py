"""Real trajectories as h-step segments, their GRU hidden states, the model pool, the mix.

Faithful to `AIDefender/SRPO offlinerl/utils/loader.py` (`restore_pool_d4rl`,
`reset_hidden_state`) and `offlinerl/utils/simple_replay_pool.py` (`SimpleReplayTrajPool`):

- each episode is cut from its start into consecutive, non-overlapping segments of h steps
  (the last one shorter, padded and masked by `valid`); `last_actions` is a_{t−1}, zero at an
  episode's first step;
- the policy's and the critics' hidden state *before* every step comes from running their GRU
  along the whole episode from a zero state (400 episodes per call, as the port); MAPLE
  refreshes them every few epochs (SRPO: every 4);
- model segments go to a ring buffer (the port's `model_pool`, 250k segments);
- a train batch of B segments is ⌊0.05·B⌋ real and the rest model segments (`real_data_ratio`,
  `get_train_policy_batch`), cut to the longest valid length in the batch (`train_policy`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

SEGMENT_KEYS = ("obs", "actions", "next_obs", "last_actions", "rewards", "terminateds", "valid")
HIDDEN_KEYS = ("policy_hidden", "value_hidden")

HiddenFn = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""(obs [B, T, o], last actions [B, T, a]) → GRU outputs [B, T, H] from a zero state."""


@dataclass
class Trajectories:
    """The real data, flat, in episode order."""

    obs: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    next_obs: np.ndarray
    terminateds: np.ndarray
    last_actions: np.ndarray
    starts: np.ndarray
    """Row of each episode's first step."""
    lengths: np.ndarray
    dynamics_ids: np.ndarray
    """Per row: which part of the data (dynamics) the episode came from."""

    @classmethod
    def from_episodes(
        cls,
        episodes: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray, bool]],
        dynamics_ids: Sequence[int] | None = None,
    ) -> Trajectories:
        """From (obs [T+1, o], actions [T, a], rewards [T], terminated) per episode."""
        if not episodes:
            raise ValueError("Trajectories: no episodes")
        obs, acts, rews, nxt, term, last, lens, dyn = [], [], [], [], [], [], [], []
        for i, (o, a, r, done) in enumerate(episodes):
            t = len(a)
            if t == 0 or len(o) != t + 1 or len(r) != t:
                raise ValueError(
                    f"episode {i}: expected obs [T+1], actions [T], rewards [T] with T >= 1, "
                    f"got {len(o)}, {len(a)}, {len(r)}"
                )
            obs.append(o[:-1])
            nxt.append(o[1:])
            acts.append(a)
            rews.append(r)
            tm = np.zeros(t, dtype=bool)
            tm[-1] = bool(done)
            term.append(tm)
            last.append(np.concatenate([np.zeros_like(a[:1]), a[:-1]]))
            lens.append(t)
            dyn.append(np.full(t, 0 if dynamics_ids is None else int(dynamics_ids[i])))
        lengths = np.asarray(lens)
        return cls(
            obs=np.concatenate(obs).astype(np.float32),
            actions=np.concatenate(acts).astype(np.float32),
            rewards=np.concatenate(rews).astype(np.float32),
            next_obs=np.concatenate(nxt).astype(np.float32),
            terminateds=np.concatenate(term),
            last_actions=np.concatenate(last).astype(np.float32),
            starts=np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64),
            lengths=lengths,
            dynamics_ids=np.concatenate(dyn).astype(np.int64),
        )

    def __len__(self) -> int:
        return len(self.obs)


def segment_starts(
    starts: np.ndarray, lengths: np.ndarray, h: int
) -> tuple[np.ndarray, np.ndarray]:
    """(first row, length) of every segment: each episode cut from its start into h-step
    pieces, the last one shorter."""
    first, size = [], []
    for s, n in zip(starts.tolist(), lengths.tolist(), strict=True):
        offs = np.arange(0, n, h)
        first.append(s + offs)
        size.append(np.minimum(h, n - offs))
    return np.concatenate(first), np.concatenate(size)


def episode_hiddens(traj: Trajectories, hidden_fn: HiddenFn, per_call: int = 400) -> np.ndarray:
    """The GRU state before every row, `[N, H]` (zero at each episode's first step)."""
    out: np.ndarray | None = None
    for i in range(0, len(traj.starts), per_call):
        starts, lens = traj.starts[i : i + per_call], traj.lengths[i : i + per_call]
        tmax = int(lens.max())
        obs = np.zeros((len(starts), tmax, traj.obs.shape[1]), dtype=np.float32)
        last = np.zeros((len(starts), tmax, traj.actions.shape[1]), dtype=np.float32)
        for j, (s, n) in enumerate(zip(starts.tolist(), lens.tolist(), strict=True)):
            obs[j, :n] = traj.obs[s : s + n]
            last[j, :n] = traj.last_actions[s : s + n]
        h = hidden_fn(obs, last)
        if out is None:
            out = np.zeros((len(traj), h.shape[-1]), dtype=np.float32)
        for j, (s, n) in enumerate(zip(starts.tolist(), lens.tolist(), strict=True)):
            out[s + 1 : s + n] = h[j, : n - 1]
    assert out is not None
    return out


class RealSegments:
    """The real data as h-step segments (gathered from the flat arrays on demand)."""

    def __init__(self, traj: Trajectories, h: int, hidden_dims: tuple[int, int] = (0, 0)) -> None:
        self.traj, self.h = traj, h
        self.first, self.size = segment_starts(traj.starts, traj.lengths, h)
        n = len(traj)
        self.hidden = {
            "policy_hidden": np.zeros((n, hidden_dims[0]), dtype=np.float32),
            "value_hidden": np.zeros((n, hidden_dims[1]), dtype=np.float32),
        }

    def __len__(self) -> int:
        return len(self.first)

    def set_hiddens(self, policy: np.ndarray, value: np.ndarray) -> None:
        """Per-row hidden states (from `episode_hiddens`)."""
        self.hidden = {"policy_hidden": policy, "value_hidden": value}

    def gather(self, idx: np.ndarray) -> dict[str, np.ndarray]:
        """Segments `idx` as `[len(idx), h, ·]` arrays plus their start hidden states."""
        steps = np.arange(self.h)
        valid = steps[None, :] < self.size[idx, None]
        rows = np.where(valid, self.first[idx, None] + steps[None, :], self.first[idx, None])
        t = self.traj
        out = {
            "obs": t.obs[rows],
            "actions": t.actions[rows],
            "next_obs": t.next_obs[rows],
            "last_actions": t.last_actions[rows],
            "rewards": t.rewards[rows],
            "terminateds": t.terminateds[rows] & valid,
            "valid": valid,
        }
        for k in ("obs", "actions", "next_obs", "last_actions", "rewards"):
            out[k] = np.where(_expand(valid, out[k]), out[k], 0).astype(np.float32)
        start = self.first[idx]
        out.update({k: v[start] for k, v in self.hidden.items()})
        return out

    def sample(self, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """`n` segments drawn uniformly with replacement (`random_batch`)."""
        return self.gather(rng.integers(0, len(self), size=n))

    def sample_starts(self, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """`n` rollout starts: dataset steps drawn uniformly, with their last action and the
        hidden states before them (`random_batch_for_initial`)."""
        rows = rng.integers(0, len(self.traj), size=n)
        return {
            "obs": self.traj.obs[rows],
            "last_actions": self.traj.last_actions[rows],
            **{k: v[rows] for k, v in self.hidden.items()},
        }


def _expand(mask: np.ndarray, like: np.ndarray) -> np.ndarray:
    return mask.reshape(mask.shape + (1,) * (like.ndim - mask.ndim))


class SegmentPool:
    """A ring buffer of model segments (`[capacity, h, ·]` arrays)."""

    def __init__(self, capacity: int) -> None:
        if capacity < 1:
            raise ValueError(f"model_pool_size={capacity} is invalid: allowed an integer >= 1")
        self.capacity = capacity
        self.data: dict[str, np.ndarray] = {}
        self.pointer = 0
        self.size = 0

    def __len__(self) -> int:
        return self.size

    def add(self, segments: dict[str, np.ndarray]) -> None:
        """Append segments (the oldest are overwritten once full)."""
        n = len(segments["obs"])
        if not self.data:
            self.data = {
                k: np.zeros((self.capacity, *v.shape[1:]), dtype=v.dtype)
                for k, v in segments.items()
            }
        if n > self.capacity:
            segments = {k: v[-self.capacity :] for k, v in segments.items()}
            n = self.capacity
        idx = (self.pointer + np.arange(n)) % self.capacity
        for k, v in segments.items():
            self.data[k][idx] = v
        self.pointer = int((self.pointer + n) % self.capacity)
        self.size = min(self.capacity, self.size + n)

    def get_state(self) -> dict[str, Any]:
        """The pool's segments and ring position (for checkpoints)."""
        data = {k: v[: self.size] for k, v in self.data.items()}
        return {"pointer": self.pointer, "data": data}

    def set_state(self, state: dict[str, Any]) -> None:
        """Back to a `get_state()` (of a pool of any capacity: the newest segments are kept)."""
        self.data, self.pointer, self.size = {}, 0, 0
        data = state["data"]
        n = len(next(iter(data.values()))) if data else 0
        if n:  # oldest first (from the ring position), so that `add` keeps the newest
            order = np.roll(np.arange(n), -int(state["pointer"]))
            self.add({k: v[order] for k, v in data.items()})

    def sample(self, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """`n` segments drawn uniformly with replacement."""
        if self.size == 0:
            raise ValueError("the model pool is empty: roll the model out first")
        idx = rng.integers(0, self.size, size=n)
        return {k: v[idx] for k, v in self.data.items()}


def mix_sizes(batch_size: int, real_ratio: float) -> tuple[int, int]:
    """(real, model) segments of a batch: int(B·ratio) real, the rest model
    (`get_train_policy_batch`)."""
    real = int(batch_size * real_ratio)
    return real, batch_size - real


def mixed_batch(
    real: RealSegments,
    pool: SegmentPool | None,
    batch_size: int,
    real_ratio: float,
    rng: np.random.Generator,
) -> dict[str, np.ndarray]:
    """A train batch: real segments first, then model segments, with `is_real` per segment,
    cut to the longest valid length (`train_policy`). Without a model pool (or ratio 1) all
    segments are real."""
    n_real, n_model = mix_sizes(batch_size, real_ratio)
    if pool is None or n_model == 0:
        n_real, n_model = batch_size, 0
    parts = [real.sample(n_real, rng)]
    if n_model:
        parts.append(pool.sample(n_model, rng))
    keys = SEGMENT_KEYS + HIDDEN_KEYS
    batch = {k: np.concatenate([p[k] for p in parts]) for k in keys}
    batch["is_real"] = np.concatenate([np.ones(n_real, bool), np.zeros(n_model, bool)])
    return trim(batch)


def trim(batch: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Cut the time axis to the longest valid segment of the batch."""
    t = int(batch["valid"].sum(1).max())
    return {k: (v[:, :t] if k in SEGMENT_KEYS else v) for k, v in batch.items()}
