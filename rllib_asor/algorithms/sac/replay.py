"""A uniform replay buffer of flat, preallocated numpy arrays for SAC-style learners.

RLlib 2.60's `EpisodeReplayBuffer` keeps whole episodes and, for every sampled transition,
slices a new one-step `SingleAgentEpisode` out of them; the Learner's connector pipeline then
walks those 256 episodes again to build the train batch. Measured on Hopper (docs/speed.md,
docs/results.md) that was ~55 ms of buffer and ~19 ms of connector time per gradient step.

`FlatReplayBuffer` stores each transition once, as rows of fixed arrays
(obs, action, reward, next obs, terminated, truncated), in a ring of `capacity` rows, and
samples uniformly with replacement (SB3's and CleanRL's buffer). `sample()` returns
`[FlatTransitions]`: one object holding the sampled columns, which our fast Learners
(`rllib_asor.rllib.learners.FastSACLearnerMixin`) turn into the train batch directly. It is
for single-agent SAC with n_step 1. RLlib's SAC config validation accepts only its own buffer
type names and RLlib's learner cannot read `FlatTransitions`, so use it through
`fast_off_policy(config)` (rllib_asor/algorithms/sac/fast.py), which installs it at algorithm init
and sets a Learner that reads it.

Checkpoints: RLlib 2.60's new-stack `Algorithm.save_to_path` stores no replay buffer (its own
neither), so a restored run refills the buffer from its next samples. `get_state()` /
`set_state()` hold the filled rows, write position and sampling RNG for whoever saves a buffer.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from ray.rllib.core.columns import Columns
from ray.rllib.utils.replay_buffers.episode_replay_buffer import EpisodeReplayBuffer

MINIBATCH_KEY = "fast_off_policy_minibatch"
"""`learner_config_dict` key: rows per gradient step when a Learner call carries several
(set by `fast_off_policy`, read by `FastSACLearnerMixin`)."""

FIELDS = (
    Columns.OBS,
    Columns.ACTIONS,
    Columns.REWARDS,
    Columns.NEXT_OBS,
    Columns.TERMINATEDS,
    Columns.TRUNCATEDS,
)


class FlatTransitions:
    """Sampled transitions as flat numpy columns, passed to the Learner in place of episodes.

    Behaves enough like an episode for RLlib's plumbing: `len()` is the number of rows (env
    steps counted by the LearnerGroup) and slicing splits the rows (LearnerGroup shards a list
    of episodes over several Learners by slicing)."""

    def __init__(self, columns: dict[str, np.ndarray]) -> None:
        self.columns = columns

    def __len__(self) -> int:
        return len(self.columns[Columns.REWARDS])

    def __getitem__(self, item: slice) -> FlatTransitions:
        if not isinstance(item, slice):
            raise TypeError("FlatTransitions supports slices only")
        return FlatTransitions({k: v[item] for k, v in self.columns.items()})

    def slice(self, item: slice, **kwargs: Any) -> FlatTransitions:
        return self[item]

    def get_return(self) -> float:  # some RLlib code logs episode returns of what it trains
        return float(self.columns[Columns.REWARDS].sum())


class FlatReplayBuffer(EpisodeReplayBuffer):
    """Uniform replay of single transitions in preallocated arrays (see module docstring)."""

    def __init__(self, capacity: int = 1_000_000, *, seed: int | None = None, **kwargs: Any):
        super().__init__(capacity=capacity, **kwargs)
        self.capacity = int(capacity)
        self._cols: dict[str, np.ndarray] | None = None
        self._size = 0
        self._pos = 0
        self._added = 0
        self.sampled_timesteps = 0
        self.rng = np.random.default_rng(seed)

    def __len__(self) -> int:
        return self._size

    def get_num_timesteps(self) -> int:
        return self._size

    def get_added_timesteps(self) -> int:
        return self._added

    def get_num_episodes(self) -> int:  # rows are transitions; there are no stored episodes
        return 0

    def _allocate(self, first: dict[str, np.ndarray]) -> None:
        self._cols = {
            k: np.zeros((self.capacity, *v.shape[1:]), dtype=v.dtype) for k, v in first.items()
        }

    def add(self, episodes: Any) -> None:
        """Append every completed step of the given episode chunks."""
        if not isinstance(episodes, list):
            episodes = [episodes]
        parts = []
        for ep in episodes:
            n = len(ep)
            if n == 0:
                continue
            if not hasattr(ep, "get_observations") or hasattr(ep, "agent_episodes"):
                raise ValueError(
                    "FlatReplayBuffer stores single-agent episodes only; use RLlib's "
                    "MultiAgentEpisodeReplayBuffer for multi-agent SAC"
                )
            obs = np.asarray(ep.get_observations(slice(0, n + 1)))
            if obs.dtype == np.float64:
                obs = obs.astype(np.float32)
            done = np.zeros(n, dtype=bool)
            trunc = np.zeros(n, dtype=bool)
            done[-1] = bool(ep.is_terminated)
            trunc[-1] = bool(ep.is_truncated)
            actions = np.asarray(ep.get_actions(slice(0, n)))
            parts.append(
                {
                    Columns.OBS: obs[:-1],
                    Columns.ACTIONS: actions,
                    Columns.REWARDS: np.asarray(ep.get_rewards(slice(0, n)), dtype=np.float32),
                    Columns.NEXT_OBS: obs[1:],
                    Columns.TERMINATEDS: done,
                    Columns.TRUNCATEDS: trunc,
                }
            )
        if not parts:
            return
        new = {k: np.concatenate([p[k] for p in parts]) for k in FIELDS}
        if self._cols is None:
            self._allocate(new)
        self._write(new)
        self.metrics.log_value("num_env_steps_added", len(new[Columns.REWARDS]), reduce="sum")

    def _write(self, new: dict[str, np.ndarray]) -> None:
        n = len(new[Columns.REWARDS])
        self._added += n
        if n >= self.capacity:  # keep the newest `capacity` rows
            new = {k: v[-self.capacity :] for k, v in new.items()}
            n = self.capacity
        idx = (self._pos + np.arange(n)) % self.capacity
        for k, v in new.items():
            self._cols[k][idx] = v
        self._pos = int((self._pos + n) % self.capacity)
        self._size = min(self._size + n, self.capacity)

    def sample(
        self,
        num_items: int | None = None,
        *,
        batch_size_B: int | None = None,
        n_step: int | tuple | None = 1,
        **kwargs: Any,
    ) -> list[FlatTransitions]:
        """`num_items` transitions drawn uniformly with replacement, as `[FlatTransitions]`."""
        if n_step not in (None, 1):
            raise ValueError(
                f"FlatReplayBuffer supports n_step=1 only, got n_step={n_step!r}; "
                "use RLlib's EpisodeReplayBuffer for n-step returns"
            )
        if self._size == 0:
            raise ValueError("FlatReplayBuffer.sample() on an empty buffer")
        n = int(num_items or batch_size_B or self.batch_size_B)
        idx = self.rng.integers(0, self._size, size=n)
        self.sampled_timesteps += n
        self.metrics.log_value("num_env_steps_sampled", n, reduce="sum")
        return [FlatTransitions({k: v[idx] for k, v in self._cols.items()})]

    def get_state(self) -> dict[str, Any]:
        cols = None
        if self._cols is not None:
            cols = {k: v[: self._size].copy() for k, v in self._cols.items()}
        return {
            "columns": cols,
            "size": self._size,
            "pos": self._pos,
            "added": self._added,
            "sampled_timesteps": self.sampled_timesteps,
            "rng": self.rng.bit_generator.state,
        }

    def set_state(self, state: dict[str, Any]) -> None:
        cols = state["columns"]
        self._size = int(state["size"])
        self._pos = int(state["pos"])
        self._added = int(state["added"])
        self.sampled_timesteps = int(state["sampled_timesteps"])
        self.rng.bit_generator.state = state["rng"]
        self._cols = None
        if cols is not None:
            self._allocate({k: v[:1] for k, v in cols.items()})
            for k, v in cols.items():
                self._cols[k][: self._size] = v
