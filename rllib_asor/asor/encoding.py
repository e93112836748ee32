"""Turn batched observations/actions of any gymnasium space into flat float tensors.

The discriminator, RND and the dynamics ensemble are MLPs; they see observations through
`flatten_obs`. For Dict spaces `keys` selects a subset (e.g. the race's `agent` vector).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import torch


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
