"""RLlib's same-result speed-ups (`ray_compat.fast_rllib`): connectors built without reading
source files, with the same recorded constructor arguments (what a checkpoint restores them
from); per-step unbatching and batching without dm-tree where there is nothing to unflatten or
nest, with the same rows and batches."""

from __future__ import annotations

import inspect

import gymnasium as gym
import numpy as np
import pytest
import ray.rllib.connectors.common.batch_individual_items as batch_connector
import ray.rllib.connectors.connector_v2 as connector_v2
import ray.rllib.connectors.module_to_env.unbatch_to_individual_items as unbatch_connector
import ray.rllib.env.single_agent_env_runner as single_agent_env_runner
import ray.rllib.env.utils.infinite_lookback_buffer as lookback_buffer
import torch
from ray.rllib.connectors.connector_v2 import ConnectorV2
from ray.rllib.utils.spaces.space_utils import BatchedNdArray, batch, unbatch

from rllib_asor import ray_compat


class Scaled(ConnectorV2):
    def __init__(self, input_observation_space=None, input_action_space=None, *, scale=2.0, **kw):
        super().__init__(input_observation_space, input_action_space, **kw)
        self.scale = scale

    def __call__(self, *, batch, **kwargs):
        return batch


def test_the_stack_holds_the_frames_inspect_stack_holds() -> None:
    ours, theirs = ray_compat._stack_without_source(), inspect.stack(0)
    assert [f.frame for f in ours] == [f.frame for f in theirs]
    assert [(f.filename, f.function) for f in ours] == [(f.filename, f.function) for f in theirs]
    assert all(f.code_context is None for f in ours)


def test_a_connector_records_the_same_constructor_arguments_as_with_rllibs_inspect() -> None:
    ray_compat.fast_connector_init()
    patched = connector_v2.inspect
    assert patched is not inspect and patched.stack is not inspect.stack
    space = gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
    try:
        connector_v2.inspect = inspect  # RLlib as shipped
        expected = Scaled(space, None, scale=3.0).get_ctor_args_and_kwargs()
    finally:
        connector_v2.inspect = patched
    got = Scaled(space, None, scale=3.0).get_ctor_args_and_kwargs()
    assert got == expected and got[1]["scale"] == 3.0
    assert got[1]["input_observation_space"] == space
    ray_compat.fast_connector_init()  # again: nothing changes
    assert connector_v2.inspect is patched


def _same(a, b) -> bool:
    if isinstance(a, dict):
        return type(a) is type(b) and list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, tuple | list):
        return type(a) is type(b) and len(a) == len(b) and all(map(_same, a, b))
    return type(a) is type(b) and np.array_equal(np.asarray(a), np.asarray(b))


RNG = np.random.default_rng(0)
BATCHES = {
    "actions": RNG.integers(0, 3, (8, 8)),
    "logp": RNG.normal(size=8).astype(np.float32),
    "obs dict, keys unsorted": {"z": RNG.normal(size=(4, 2)), "a": RNG.normal(size=(4, 3, 3))},
    "nested dict": {"a": {"b": np.arange(3)}, "c": np.arange(3.0)},
    "tuple": (np.arange(3), np.ones((3, 2))),
    "torch": torch.arange(6).reshape(3, 2),
    "one row": np.zeros((1, 5)),
}


@pytest.mark.parametrize("name", sorted(BATCHES))
def test_unbatch_gives_rllibs_rows(name: str) -> None:
    batch = BATCHES[name]
    ours, theirs = ray_compat._unbatch(batch), unbatch(batch)
    assert len(ours) == len(theirs) and all(map(_same, ours, theirs))


def test_the_per_step_callers_unbatch_with_it() -> None:
    ray_compat.fast_rllib()
    assert single_agent_env_runner.unbatch is ray_compat._unbatch
    assert unbatch_connector.unbatch_fn is ray_compat._unbatch
    ray_compat.fast_rllib()  # again: nothing changes
    assert single_agent_env_runner.unbatch is ray_compat._unbatch


def _obs(rng: np.random.Generator, order: str = "za") -> dict:
    parts = {"z": rng.normal(size=(2, 3)).astype(np.float32), "a": rng.integers(0, 4, (5,))}
    return {k: parts[k] for k in order}


ROWS = {
    "obs dicts, keys unsorted": [_obs(RNG) for _ in range(4)],
    "one obs dict": [_obs(RNG)],
    "keys in another order per row": [_obs(RNG, "za"), _obs(RNG, "az")],
    "a float64 row among float32 rows": [_obs(RNG), {**_obs(RNG), "z": np.ones((2, 3))}],
    "nested dicts": [{"a": {"b": np.arange(3)}, "c": np.arange(2.0)} for _ in range(3)],
    "tuples": [(np.arange(3), np.ones(2)) for _ in range(3)],
    "arrays": [np.arange(3) for _ in range(3)],
    "scalars": [1.0, 2.0, 3.0],
    "already batched": [{"a": BatchedNdArray(np.ones((2, 3)))} for _ in range(2)],
}


@pytest.mark.parametrize("name", sorted(ROWS))
def test_batch_gives_rllibs_batch(name: str) -> None:
    rows = ROWS[name]
    for already in (False, "auto"):
        ours = ray_compat._batch(rows, individual_items_already_have_batch_dim=already)
        theirs = batch(rows, individual_items_already_have_batch_dim=already)
        assert _same(ours, theirs)
        leaves = ours.values() if isinstance(ours, dict) else [ours]
        assert [v.dtype for v in leaves if isinstance(v, np.ndarray)] == [
            v.dtype for v in (theirs.values() if isinstance(theirs, dict) else [theirs])
            if isinstance(v, np.ndarray)
        ]


@pytest.mark.parametrize(
    "rows",
    [
        [{"a": np.ones(2)}, {"b": np.ones(2)}],  # other keys
        [{"a": np.ones(2)}, {"a": [1.0, 1.0]}],  # a list where the first row has an array
    ],
    ids=["other keys", "list leaf"],
)
def test_batch_refuses_what_rllib_refuses(rows: list) -> None:
    with pytest.raises(Exception) as theirs:
        batch(rows)
    with pytest.raises(type(theirs.value)):
        ray_compat._batch(rows)


def test_an_episode_chunk_and_the_env_to_module_pipeline_batch_with_it() -> None:
    ray_compat.fast_rllib()
    assert lookback_buffer.batch is ray_compat._batch
    assert batch_connector.batch_fn is ray_compat._batch
    ray_compat.fast_rllib()  # again: nothing changes
    assert lookback_buffer.batch is ray_compat._batch
