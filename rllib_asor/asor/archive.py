"""A persistent archive of the states of the highest-return episodes, per dynamics.

ASOR's "real" set D_P is drawn from here instead of from the current on-policy batch (the
pattern of generative adversarial self-imitation, Guo et al. 2018): the current batch is
"generated", and the discriminator learns what the best episodes seen so far under *every*
dynamics have in common. Each dynamics bucket (`dynamics_id` modulo the bucket count; one
bucket when the env reports none) keeps up to `capacity` states; when full, the states of the
lowest-return episodes go first, and among equal returns the oldest.

Episodes reach the learner in chunks; `add_chunk` accumulates them by episode key and an
episode enters the archive when it terminates or when it stops arriving (truncated by the env
at a chunk boundary). The stored tensors are buffers, so the archive survives checkpoints; the
open, unfinished episodes do not (at most one batch of chunks is lost on restore).
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import nn


@dataclass
class _OpenEpisode:
    features: list[torch.Tensor] = field(default_factory=list)
    rewards: list[torch.Tensor] = field(default_factory=list)
    dynamics_id: int = 0
    seen_in_call: int = 0
    terminated: bool = False


class StateArchive(nn.Module):
    """Top-return episodes' states per dynamics bucket, with each state's return-to-go."""

    def __init__(self, feature_dim: int, capacity: int = 2048, buckets: int = 8) -> None:
        super().__init__()
        self.capacity, self.buckets = int(capacity), int(buckets)
        self.register_buffer("features", torch.zeros(buckets, capacity, feature_dim))
        self.register_buffer("returns", torch.full((buckets, capacity), -torch.inf))
        self.register_buffer("return_to_go", torch.zeros(buckets, capacity))
        self.register_buffer("stamp", torch.zeros(buckets, capacity))
        self.register_buffer("size", torch.zeros(buckets))
        self.register_buffer("episodes_added", torch.zeros(()))
        self._open: dict[Hashable, _OpenEpisode] = {}
        self._calls = 0

    # ------------------------------------------------------------------ filling
    def add_chunk(
        self,
        key: Hashable,
        features: torch.Tensor,
        rewards: torch.Tensor,
        dynamics_id: int,
        terminated: bool,
        gamma: float,
    ) -> None:
        """Append one chunk of an episode; a terminated episode is archived at the call's
        `end_call` (with the others of that call: one sort per bucket, not one per episode)."""
        ep = self._open.setdefault(key, _OpenEpisode(dynamics_id=int(dynamics_id)))
        ep.features.append(features.detach().float().cpu())
        ep.rewards.append(rewards.detach().float().cpu())
        ep.seen_in_call = self._calls
        ep.terminated = ep.terminated or terminated

    def end_call(self, gamma: float) -> None:
        """Archive the episodes that terminated in this call and the open ones that received no
        chunk since the last `end_call` (the env truncated them); call once per batch, after
        all `add_chunk`s. All closing episodes go through one return-to-go pass and one sort
        per bucket (a batch of a short-episode env closes hundreds)."""
        keys = [k for k, ep in self._open.items() if ep.terminated or ep.seen_in_call < self._calls]
        closing = [ep for ep in map(self._open.pop, keys) if any(len(r) for r in ep.rewards)]
        self._calls += 1
        if not closing:
            return
        lengths = [sum(len(r) for r in ep.rewards) for ep in closing]
        rewards = torch.cat([r for ep in closing for r in ep.rewards])
        returns = np.add.reduceat(rewards.double().cpu().numpy(), np.cumsum([0, *lengths[:-1]]))
        self._insert(
            torch.cat([f for ep in closing for f in ep.features]),
            discounted_return_to_go(rewards, gamma, lengths),
            lengths,
            returns.tolist(),
            [ep.dynamics_id for ep in closing],
        )

    def insert(
        self,
        features: torch.Tensor,
        return_to_go: torch.Tensor,
        episode_return: float,
        dynamics_id: int,
    ) -> None:
        """Insert one whole episode; keep the bucket's `capacity` best states."""
        self.insert_many([(features, return_to_go, episode_return, dynamics_id)])

    def insert_many(self, episodes: list[tuple[torch.Tensor, torch.Tensor, float, int]]) -> None:
        """Insert whole episodes (features, return-to-go, episode return, dynamics id), stamped
        in list order; each bucket keeps its `capacity` best states: highest episode return
        first, among equal returns the newest first (what inserting them one by one keeps)."""
        if episodes:
            self._insert(
                torch.cat([f for f, *_ in episodes]),
                torch.cat([g for _, g, *_ in episodes]),
                [len(f) for f, *_ in episodes],
                [float(r) for *_, r, _ in episodes],
                [int(d) for *_, d in episodes],
            )

    @torch.no_grad()
    def _insert(
        self,
        features: torch.Tensor,
        return_to_go: torch.Tensor,
        lengths: list[int],
        returns: list[float],
        dynamics_ids: list[int],
    ) -> None:
        """`insert_many` on the episodes' rows back to back (`lengths` rows each)."""
        dev = features.device  # the rows' bookkeeping beside the rows
        counts = torch.tensor(lengths, device=dev)
        first = float(self.episodes_added) + 1.0
        self.episodes_added += len(lengths)
        bucket = torch.tensor(dynamics_ids, device=dev) % self.buckets
        rets = torch.tensor(returns, dtype=self.returns.dtype, device=dev)
        stamps = first + torch.arange(len(lengths), dtype=self.stamp.dtype, device=dev)
        bucket, rets, stamps = (x.repeat_interleave(counts) for x in (bucket, rets, stamps))
        for b in bucket.unique().tolist():
            rows = bucket == b
            n = int(self.size[b])
            feats = torch.cat([self.features[b, :n], features[rows].to(self.features)])
            rtg = torch.cat([self.return_to_go[b, :n], return_to_go[rows].to(self.return_to_go)])
            ret = torch.cat([self.returns[b, :n], rets[rows].to(self.returns)])
            stamp = torch.cat([self.stamp[b, :n], stamps[rows].to(self.stamp)])
            order = torch.argsort(stamp, descending=True, stable=True)
            order = order[torch.argsort(ret[order], descending=True, stable=True)][: self.capacity]
            k = len(order)
            self.features[b, :k], self.returns[b, :k] = feats[order], ret[order]
            self.return_to_go[b, :k], self.stamp[b, :k] = rtg[order], stamp[order]
            self.returns[b, k:] = -torch.inf
            self.size[b] = k

    # ------------------------------------------------------------------ reading
    def __len__(self) -> int:
        return int(self.size.sum())

    @property
    def open_episodes(self) -> int:
        """Episodes with chunks received but not yet archived."""
        return len(self._open)

    def sample(
        self, n: int, generator: torch.Generator | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Up to n (features, return-to-go) drawn evenly over the non-empty buckets,
        without replacement inside a bucket, on the archive's device. The permutations are
        drawn on `generator`'s device (the same draws wherever the archive lives)."""
        device = self.features.device
        filled = [b for b, size in enumerate(self.size.tolist()) if size > 0]
        if not filled or n <= 0:
            dim = self.features.shape[-1]
            return torch.zeros(0, dim, device=device), torch.zeros(0, device=device)
        per = -(-n // len(filled))
        draw_on = generator.device if generator is not None else device
        feats, rtg = [], []
        for b in filled:
            size = int(self.size[b])
            perm = torch.randperm(size, generator=generator, device=draw_on)
            idx = perm[: min(per, size)].to(device)
            feats.append(self.features[b, idx])
            rtg.append(self.return_to_go[b, idx])
        return torch.cat(feats), torch.cat(rtg)

    def bucket_sizes(self) -> list[int]:
        """States stored per bucket."""
        return [int(s) for s in self.size]


def discounted_return_to_go(
    rewards: torch.Tensor, gamma: float, lengths: list[int] | None = None
) -> torch.Tensor:
    """G_t = Σ_k γ^k r_{t+k} within one episode (float32, shape like `rewards`); with
    `lengths`, within each of several episodes stored back to back.

    The recurrence G_t = r_t + γ·G_{t+1} as a linear filter over the reversed rewards, in
    float64 (scipy's `lfilter`), once over all the episodes; each episode then drops what the
    filter carried in from the episodes after it: γ^(e−t)·H_e, e its end and H the filter's
    output.
    """
    from scipy.signal import lfilter

    r = rewards.detach().cpu().double().numpy()
    g = lfilter([1.0], [1.0, -float(gamma)], r[::-1])[::-1].copy()
    if lengths is not None and len(lengths) > 1:
        ends = np.repeat(np.cumsum(lengths), lengths)
        t = np.flatnonzero(ends < len(r))
        g[t] -= float(gamma) ** (ends[t] - t) * g[ends[t]]
    return torch.from_numpy(g).float()
