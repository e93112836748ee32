"""RLlib's connectors are built without reading source files (`ray_compat.fast_connector_init`),
with the same recorded constructor arguments (what a checkpoint restores them from)."""

from __future__ import annotations

import inspect

import gymnasium as gym
import numpy as np
import ray.rllib.connectors.connector_v2 as connector_v2
from ray.rllib.connectors.connector_v2 import ConnectorV2

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
