"""RLlib's compiled Learner update (`torch_compile_learner`, what docs/cluster.md names for a
GPU Learner's per-minibatch launch cost) runs the race PPO+ASOR Learner and arrives at the same
weights as the eager one. Checked on the CPU with the `aot_eager` backend (the eager kernels
through dynamo's graphs: the same arithmetic, seconds to compile); inductor and CUDA graphs are
measured by `make gpu-check`."""

import copy

import torch
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

import game_env
import rllib_asor
from rllib_asor.race.config import RACE_ASOR_OBS_KEYS, race_ppo_config

SPACES = {DEFAULT_MODULE_ID: (game_env.observation_space(), game_env.action_space())}


def config(compiled: bool):
    c = race_ppo_config(max_episode_steps=20).training(
        train_batch_size=64, minibatch_size=32, num_epochs=2
    )
    if compiled:
        c = c.framework(
            torch_compile_learner=True,
            torch_compile_learner_what_to_compile="complete_update",
            torch_compile_learner_dynamo_backend="aot_eager",
        )
    c = rllib_asor.with_asor(c, mode="asor", obs_keys=list(RACE_ASOR_OBS_KEYS), seed=3)
    return c.debugging(seed=3)


def test_the_compiled_update_of_race_ppo_asor_equals_the_eager_one(race_episodes):
    weights, start = {}, None
    for compiled in (False, True):
        learner = config(compiled).build_learner(spaces=SPACES)
        policy = learner.module[DEFAULT_MODULE_ID]
        if start is None:
            start = {n: p.detach().clone() for n, p in policy.named_parameters()}
        for _ in range(2):  # the second update runs the compiled graph without recompiling
            learner.update(
                episodes=copy.deepcopy(race_episodes),
                timesteps={NUM_ENV_STEPS_SAMPLED_LIFETIME: 64},
                num_epochs=2,
                minibatch_size=32,
                shuffle_batch_per_epoch=False,
            )
        assert learner._torch_compile_complete_update is compiled
        weights[compiled] = {n: p.detach().clone() for n, p in policy.named_parameters()}
    moved = sum(not torch.equal(w, start[n]) for n, w in weights[False].items())
    assert moved > 50  # the updates changed (nearly) every parameter
    for name, w in weights[False].items():
        torch.testing.assert_close(weights[True][name], w, rtol=1e-5, atol=1e-6, msg=name)
