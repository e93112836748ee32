"""What the discriminator, RND and the dynamics ensemble are built from: their inputs and
their layers.

Inputs: batched observations/actions of any gymnasium space become flat float tensors
(`flatten`); for Dict spaces `keys` selects a subset (e.g. the race's `agent` vector,
`select`, `select_space`). Layers: a ReLU MLP (`mlp`) and a running mean/std normaliser
(`RunningMeanStd`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn


def select_space(space: gym.Space, keys: Sequence[str] | None) -> gym.Space:
    """The sub-space the aux networks see: `space` itself, or the Dict restricted to `keys`."""
    if keys is None:
        return space
    if not isinstance(space, gym.spaces.Dict):
        raise ValueError(
            f"asor.obs_keys={list(keys)!r} needs a Dict observation space, got {space}"
        )
    missing = [k for k in keys if k not in space.spaces]
    if missing:
        raise ValueError(
            f"asor.obs_keys: {missing!r} not in the observation space; allowed: "
            f"{sorted(space.spaces)}"
        )
    return gym.spaces.Dict({k: space.spaces[k] for k in keys})


def flat_dim(space: gym.Space) -> int:
    """Length of `flatten(x, space)` for one sample."""
    if isinstance(space, gym.spaces.Box):
        return int(np.prod(space.shape))
    if isinstance(space, gym.spaces.Discrete):
        return int(space.n)
    if isinstance(space, gym.spaces.MultiDiscrete):
        return int(np.sum(space.nvec))
    if isinstance(space, gym.spaces.MultiBinary):
        return int(np.prod(space.shape))
    if isinstance(space, gym.spaces.Dict):
        return sum(flat_dim(s) for s in space.spaces.values())
    if isinstance(space, gym.spaces.Tuple):
        return sum(flat_dim(s) for s in space.spaces)
    raise ValueError(
        f"ASOR cannot encode observation space {space}: allowed Box, Discrete, "
        "MultiDiscrete, MultiBinary, Dict, Tuple"
    )


def flatten(x: Any, space: gym.Space) -> torch.Tensor:
    """Batched sample(s) of `space` ([N, ...] tensors / dicts of them) → float tensor [N, D]."""
    if isinstance(space, gym.spaces.Dict):
        if not isinstance(x, Mapping):
            raise ValueError(f"expected a dict of tensors for {space}, got {type(x).__name__}")
        return torch.cat([flatten(x[k], s) for k, s in space.spaces.items()], dim=-1)
    if isinstance(space, gym.spaces.Tuple):
        return torch.cat([flatten(xi, s) for xi, s in zip(x, space.spaces, strict=True)], dim=-1)
    if not isinstance(x, torch.Tensor):  # numpy or lists: host data, made on the CPU
        x = torch.as_tensor(x, device="cpu")
    if isinstance(space, gym.spaces.Discrete):
        return torch.nn.functional.one_hot(
            (x.long() - int(space.start)).reshape(-1), int(space.n)
        ).float()
    if isinstance(space, gym.spaces.MultiDiscrete):
        flat = x.long().reshape(x.shape[0], -1)
        nvec = np.asarray(space.nvec).reshape(-1)
        return torch.cat(
            [torch.nn.functional.one_hot(flat[:, i], int(n)).float() for i, n in enumerate(nvec)],
            dim=-1,
        )
    return x.reshape(x.shape[0], -1).float()


def select(x: Any, keys: Sequence[str] | None) -> Any:
    """Restrict a batched Dict observation to `keys` (identity when keys is None)."""
    if keys is None:
        return x
    return {k: x[k] for k in keys}


def mlp(in_dim: int, hiddens: Sequence[int], out_dim: int) -> nn.Sequential:
    """ReLU MLP in_dim → hiddens → out_dim (no output activation)."""
    layers: list[nn.Module] = []
    for h in hiddens:
        layers += [nn.Linear(in_dim, h), nn.ReLU()]
        in_dim = h
    layers.append(nn.Linear(in_dim, out_dim))
    return nn.Sequential(*layers)


class RunningMeanStd(nn.Module):
    """Running mean/variance (Chan et al. parallel update) kept as buffers.

    Buffers travel with `state_dict`, so the statistics survive checkpoint/restore. They are
    float32 because RLlib's checkpoints store module state as float32 (float64 would come back
    rounded); the update itself runs in float64.
    """

    def __init__(self, shape: int | Sequence[int], epsilon: float = 1e-4) -> None:
        super().__init__()
        shape = (shape,) if isinstance(shape, int) else tuple(shape)
        self.register_buffer("mean", torch.zeros(shape))
        self.register_buffer("var", torch.ones(shape))
        self.register_buffer("count", torch.tensor(float(epsilon)))

    @torch.no_grad()
    def update(self, x: torch.Tensor) -> None:
        """Fold a batch [N, *shape] into the statistics."""
        if x.shape[0] == 0:
            return
        x = x.detach().to(torch.float64)
        mean, var, count = self.mean.double(), self.var.double(), self.count.double()
        b_mean, b_var, b_n = x.mean(0), x.var(0, unbiased=False), x.shape[0]
        delta, total = b_mean - mean, count + b_n
        m2 = var * count + b_var * b_n + delta.pow(2) * count * b_n / total
        self.mean.copy_(mean + delta * b_n / total)
        self.var.copy_(m2 / total)
        self.count.copy_(total)

    def normalize(self, x: torch.Tensor, clip: float = 5.0) -> torch.Tensor:
        """(x − mean) / std, clipped to ±clip, in x's dtype."""
        std = torch.sqrt(self.var + 1e-8)
        return ((x - self.mean.to(x.dtype)) / std.to(x.dtype)).clamp(-clip, clip)
