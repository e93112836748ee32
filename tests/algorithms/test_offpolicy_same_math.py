"""The fast path's per-step speed-ups change no number: on a fixed batch, the fast SAC and ESCP
Learners (one backward pass per module, the next-state policy pass without autograd, no
`train()` walk per step) give the same forward outputs, losses, gradients and parameters after
several `_update`s as the same Learner running RLlib's computation (its `_forward_train` and
its per-optimizer `compute_gradients`), kept here as the reference."""

from __future__ import annotations

import types

import gymnasium as gym
import numpy as np
import pytest
import torch
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.algorithms.sac.torch.default_sac_torch_rl_module import DefaultSACTorchRLModule
from ray.rllib.algorithms.sac.torch.sac_torch_learner import SACTorchLearner
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.torch.torch_rl_module import TorchRLModule

import rllib_asor
from rllib_asor import EscpConfig
from rllib_asor.algorithms.escp.replay import DYNAMICS_ID, NEXT_WINDOW, WINDOW
from rllib_asor.algorithms.sac.fast import fast_off_policy

MID = "default_policy"
B, H = 64, 4


class TaskEnv(gym.Env):
    """Spaces only (the Learners are built from them): 3-d state, 2-d action."""

    observation_space = gym.spaces.Box(-10, 10, (3,), np.float32)
    action_space = gym.spaces.Box(-1, 1, (2,), np.float32)

    def __init__(self, config: dict | None = None) -> None:
        pass


def _sac_batch(rng: np.random.Generator) -> dict[str, np.ndarray]:
    obs = rng.normal(size=(B, 3)).astype(np.float32)
    return {
        Columns.OBS: obs,
        Columns.NEXT_OBS: obs + rng.normal(scale=0.1, size=obs.shape).astype(np.float32),
        Columns.ACTIONS: rng.uniform(-1, 1, (B, 2)).astype(np.float32),
        Columns.REWARDS: rng.normal(size=B).astype(np.float32),
        Columns.TERMINATEDS: rng.random(B) < 0.1,
        Columns.TRUNCATEDS: np.zeros(B, bool),
        "n_step": np.ones(B, np.int64),
        "weights": np.ones(B, np.float32),
    }


def _escp_batch(rng: np.random.Generator) -> dict[str, np.ndarray]:
    batch = _sac_batch(rng)
    batch[WINDOW] = rng.normal(size=(B, H, 5)).astype(np.float32)
    batch[NEXT_WINDOW] = rng.normal(size=(B, H, 5)).astype(np.float32)
    batch[DYNAMICS_ID] = rng.integers(0, 3, B)
    return batch


def _tensors(batch: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
    return {k: torch.from_numpy(v.copy()) for k, v in batch.items()}


def _sac_config() -> SACConfig:
    return (
        SACConfig()
        .environment(TaskEnv)
        .training(
            train_batch_size_per_learner=B,
            initial_alpha=0.5,
            replay_buffer_config={"type": "EpisodeReplayBuffer", "capacity": 1000},
        )
        .rl_module(model_config={"fcnet_hiddens": [32, 32]})
        .debugging(seed=0)
    )


def _escp_config(min_replay: int = 0) -> EscpConfig:
    return (
        EscpConfig()
        .environment(TaskEnv)
        .escp(history_len=H, rmdm_min_replay=min_replay, rmdm_min_task_fraction=0.0)
        .training(train_batch_size_per_learner=B)
        .debugging(seed=0)
    )


def _pair(config):
    """Two Learners with the same state; the second computes as RLlib does (the reference)."""
    env = TaskEnv()
    fast, ref = config.build_learner(env=env), config.build_learner(env=env)
    assert fast.one_backward_module(MID)  # the path under test
    ref.set_state(fast.get_state())
    module = ref.module[MID].unwrapped()
    if isinstance(module, DefaultSACTorchRLModule):
        module._forward_train_continuous = types.MethodType(
            DefaultSACTorchRLModule._forward_train_continuous, module
        )
    module.forward_train = types.MethodType(TorchRLModule.forward_train, module)
    ref.compute_gradients = types.MethodType(SACTorchLearner.compute_gradients, ref)
    if hasattr(ref, "_encoder_may_step"):  # ESCP's z with autograd whether RMDM is on or not
        ref._encoder_may_step = lambda module: True
    for learner in (fast, ref):  # ESCP: RMDM switched on, so the encoder's gradient counts
        learner.before_gradient_based_update(timesteps={"num_env_steps_sampled_lifetime": 10**6})
    return fast, ref


def _step_outputs(learner, batch, seed):
    torch.manual_seed(seed)
    module = learner.module[MID].unwrapped()
    if hasattr(learner, "_encoder_may_step"):  # as ESCP's `_update` does before the forward
        module.encoder_grad = learner._encoder_may_step(module)
    fwd = learner.module.forward_train({MID: batch})
    losses = learner.compute_losses(fwd_out=fwd, batch={MID: batch})
    temp = {k: v.detach().clone() for k, v in learner._temp_losses.items()}
    grads = learner.compute_gradients(losses)
    named = {id(p): n for n, p in module.named_parameters()}
    named[id(learner.curr_log_alpha[MID])] = "log_alpha"
    grads = {named[id(p)]: None if g is None else g.clone() for p, g in grads.items()}
    for opt in learner._optimizer_parameters:
        opt.zero_grad(set_to_none=True)
    return {k: v.detach() for k, v in fwd[MID].items()}, temp, grads


CONFIGS = {
    "sac": lambda: fast_off_policy(_sac_config()),
    "sac_asor": lambda: rllib_asor.with_asor(fast_off_policy(_sac_config()), seed=0),
    "escp": _escp_config,
    "escp_rmdm_off": lambda: _escp_config(min_replay=10**9),  # z without autograd
}


@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_forward_losses_and_gradients_equal_rllibs_computation(name: str) -> None:
    fast, ref = _pair(CONFIGS[name]())
    rng = np.random.default_rng(1)
    batch = _escp_batch(rng) if name.startswith("escp") else _sac_batch(rng)
    fwd_a, loss_a, grad_a = _step_outputs(fast, _tensors(batch), seed=7)
    fwd_b, loss_b, grad_b = _step_outputs(ref, _tensors(batch), seed=7)
    assert fwd_a.keys() == fwd_b.keys()
    for k in fwd_a:
        torch.testing.assert_close(fwd_a[k], fwd_b[k], rtol=0, atol=0, msg=k)
    assert loss_a.keys() == loss_b.keys() and len(loss_a) >= 4
    for k in loss_a:
        torch.testing.assert_close(loss_a[k], loss_b[k], rtol=0, atol=0, msg=str(k))
    assert grad_a.keys() == grad_b.keys()
    with_grad = [k for k, g in grad_b.items() if g is not None]
    assert "log_alpha" in with_grad and any(k.startswith("qf") for k in with_grad)
    if name == "escp":
        assert any(k.startswith("encoder.") for k in with_grad)  # RMDM's gradient
    if name == "escp_rmdm_off":
        assert not any(k.startswith("encoder.") for k in with_grad)
    for k in grad_a:
        if grad_b[k] is None:
            assert grad_a[k] is None, k
        else:
            torch.testing.assert_close(grad_a[k], grad_b[k], rtol=0, atol=1e-7, msg=k)


@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_parameters_after_updates_equal_rllibs_computation(name: str) -> None:
    fast, ref = _pair(CONFIGS[name]())
    rng = np.random.default_rng(2)
    escp = name.startswith("escp")
    batches = [_escp_batch(rng) if escp else _sac_batch(rng) for _ in range(3)]
    before = {k: v.clone() for k, v in fast.module[MID].unwrapped().state_dict().items()}
    for learner in (fast, ref):
        torch.manual_seed(11)
        for batch in batches:
            learner._update({MID: _tensors(batch)})
    state_a = fast.module[MID].unwrapped().state_dict()
    state_b = ref.module[MID].unwrapped().state_dict()
    for k, v in state_a.items():
        torch.testing.assert_close(v, state_b[k], rtol=0, atol=1e-6, msg=k)
    moved = {k.split(".")[0] for k, v in state_a.items() if not torch.equal(before[k], v)}
    expected = {"qf", "encoder", "pi"} if name == "escp" else {"qf", "pi"}
    if name == "escp_rmdm_off":
        assert not any(k.startswith("encoder.") for k in moved)
    assert expected <= moved, moved
    torch.testing.assert_close(fast.curr_log_alpha[MID], ref.curr_log_alpha[MID], rtol=0, atol=0)


def test_task_mean_value_pass_runs_the_encoder_only_on_rows_without_a_task_mean() -> None:
    module = _escp_config().build_learner(env=TaskEnv()).module[MID].unwrapped()
    batch = _tensors(_escp_batch(np.random.default_rng(3)))
    calls = []
    module.encoder.register_forward_hook(lambda m, i, o: calls.append(i[0].shape[0]))
    with torch.no_grad():
        window_v = module.state_values(batch)  # default: π on the window's z
        assert calls == [B]
        module.task_ids[:2] = torch.tensor([0, 1])  # tasks 0 and 1 have a mean, task 2 not
        module.task_seen[:2] = True
        module.task_means[:2] = torch.tensor([[0.3, -0.2], [-0.5, 0.1]])
        calls.clear()
        v = module.state_values(batch, context="task_mean")
        ids = batch[DYNAMICS_ID]
        assert calls == [int((ids == 2).sum())]
        z = module.task_means[ids.clamp(max=1)].clone()
        z[ids == 2] = module.context(batch[WINDOW][ids == 2])
        obs = batch[Columns.OBS]
        act = torch.tanh(module.policy_inputs(obs, z).chunk(2, -1)[0])
        torch.testing.assert_close(v, module._q(obs, act, z), rtol=0, atol=1e-6)
        # rows of a task without a mean: the window variant's value (no mean there either)
        module.task_seen[:2] = False
        torch.testing.assert_close(
            module.state_values(batch, context="task_mean"), window_v, rtol=0, atol=1e-6
        )
        module.task_seen[:3] = True
        module.task_ids[2] = 2
        calls.clear()
        module.state_values(batch, context="task_mean")
        assert calls == []
    with pytest.raises(ValueError, match="context='z' is not allowed"):
        module.state_values(batch, context="z")
