"""Flat features of every observation space the aux networks see, and one `AsorBatch` of
several Learners' batches (mutation survivors)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

from rllib_asor.asor.networks import flat_dim, flatten, select, select_space
from rllib_asor.asor.proxy import ProxyInputs
from rllib_asor.asor.update import AsorBatch, Chunk, concat_batches

BOX = gym.spaces.Box(-1, 1, (2, 3), np.float32)
DISCRETE = gym.spaces.Discrete(4, start=1)
MULTI = gym.spaces.MultiDiscrete([2, 3])
BINARY = gym.spaces.MultiBinary(3)
DICT = gym.spaces.Dict({"a": BOX, "b": DISCRETE})
TUPLE = gym.spaces.Tuple((MULTI, BINARY))


@pytest.mark.parametrize(
    "space, dim", [(BOX, 6), (DISCRETE, 4), (MULTI, 5), (BINARY, 3), (DICT, 10), (TUPLE, 8)]
)
def test_flat_dim_is_the_width_of_flatten(space, dim):
    samples = [space.sample() for _ in range(5)]
    if isinstance(space, gym.spaces.Dict):
        batch = {k: np.stack([s[k] for s in samples]) for k in space.spaces}
    elif isinstance(space, gym.spaces.Tuple):
        batch = tuple(np.stack([s[i] for s in samples]) for i in range(len(space.spaces)))
    else:
        batch = np.stack(samples)
    flat = flatten(batch, space)
    assert flat_dim(space) == dim and flat.shape == (5, dim) and flat.dtype == torch.float32


def test_flatten_one_hot_encodes_discrete_parts():
    assert flatten(np.array([1, 4]), DISCRETE).tolist() == [[1, 0, 0, 0], [0, 0, 0, 1]]
    assert flatten(np.array([[1, 2], [0, 0]]), MULTI).tolist() == [
        [0, 1, 0, 0, 1],
        [1, 0, 1, 0, 0],
    ]
    box = np.arange(12, dtype=np.float32).reshape(2, 2, 3)
    assert flatten(box, BOX).tolist() == [list(range(6)), list(range(6, 12))]
    obs = {"b": np.array([2]), "a": np.ones((1, 2, 3))}  # the space's key order, not the dict's
    assert flatten(obs, DICT).tolist() == [[1.0] * 6 + [0, 1, 0, 0]]
    tup = (np.array([[1, 0]]), np.array([[1, 0, 1]]))
    assert flatten(tup, TUPLE).tolist() == [[0, 1, 1, 0, 0, 1, 0, 1]]


def test_select_keeps_the_chosen_keys():
    space = select_space(DICT, ["b"])
    assert list(space.spaces) == ["b"] and flat_dim(space) == 4
    assert select_space(BOX, None) is BOX
    obs = {"a": 1, "b": 2}
    assert select(obs, ["b"]) == {"b": 2} and select(obs, None) is obs
    with pytest.raises(ValueError, match="Dict observation space"):
        select_space(BOX, ["a"])
    with pytest.raises(ValueError, match=r"\['c'\] not in the observation space"):
        select_space(DICT, ["a", "c"])
    with pytest.raises(ValueError, match="cannot encode"):
        flat_dim(gym.spaces.Text(5))
    with pytest.raises(ValueError, match="expected a dict"):
        flatten(np.zeros((1, 2, 3)), DICT)


def _batch(n, start, with_chunks=True, with_proxy=True):
    f = torch.arange(start, start + n, dtype=torch.float32).reshape(n, 1)
    return AsorBatch(
        features=f,
        env_rewards=f[:, 0] * 10,
        values=f[:, 0] * 100,
        gamma=0.9 if start == 0 else 0.5,
        timestep=float(start),
        proxy_inputs=ProxyInputs(f, f + 1, f + 2, f[:, 0].long()) if with_proxy else None,
        next_features=f + 0.5,
        terminateds=torch.zeros(n, dtype=torch.bool),
        next_values=f[:, 0],
        chunks=[Chunk(("k", start), 0, n, dynamics_id=start)] if with_chunks else None,
    )


def test_concat_batches_keeps_row_order_and_shifts_chunks():
    whole = concat_batches([_batch(2, 0), _batch(3, 10)])
    assert whole.features[:, 0].tolist() == [0, 1, 10, 11, 12]
    assert whole.env_rewards.tolist() == [0, 10, 100, 110, 120]
    assert whole.values.tolist() == [0, 100, 1000, 1100, 1200]
    assert whole.next_features[:, 0].tolist() == [0.5, 1.5, 10.5, 11.5, 12.5]
    assert whole.next_values.tolist() == [0, 1, 10, 11, 12]
    assert whole.terminateds.shape == (5,)
    assert (whole.gamma, whole.timestep) == (0.9, 0.0)  # from the first batch
    assert [(c.key, c.start, c.stop, c.dynamics_id) for c in whole.chunks] == [
        (("k", 0), 0, 2, 0),
        (("k", 10), 2, 5, 10),
    ]
    p = whole.proxy_inputs
    assert p.actions[:, 0].tolist() == [1, 2, 11, 12, 13]
    assert p.next_features[:, 0].tolist() == [2, 3, 12, 13, 14]
    assert p.dynamics_ids.tolist() == [0, 1, 10, 11, 12]


def test_concat_batches_drops_what_one_batch_lacks():
    whole = concat_batches([_batch(2, 0), _batch(1, 5, with_chunks=False, with_proxy=False)])
    assert whole.chunks is None and whole.proxy_inputs is None
    assert whole.features.shape == (3, 1)
    whole = concat_batches([_batch(1, 5, with_chunks=False), _batch(2, 0)])
    assert whole.chunks is None
    with pytest.raises(ValueError, match="at least one"):
        concat_batches([])
