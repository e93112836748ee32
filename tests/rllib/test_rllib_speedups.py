"""RLlib's same-result speed-ups (`ray_compat.fast_rllib`): connectors built without reading
source files, with the same recorded constructor arguments (what a checkpoint restores them
from); per-step unbatching without dm-tree where there is nothing to unflatten, with the same
rows."""

from __future__ import annotations

import inspect

import gymnasium as gym
import numpy as np
import pytest
import ray.rllib.connectors.connector_v2 as connector_v2
import ray.rllib.connectors.module_to_env.unbatch_to_individual_items as unbatch_connector
import ray.rllib.env.single_agent_env_runner as single_agent_env_runner
import torch
from ray.rllib.connectors.connector_v2 import ConnectorV2
from ray.rllib.utils.spaces.space_utils import unbatch

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
