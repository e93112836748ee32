"""UP-OSI: OSI's loss and network on hand-made tensors, the env's parameters in `info`, OSI on a
user's own env from Python (the universal policy reads the true parameters, OSI learns to
identify them), with ASOR, its checkpoint round trip, and bad settings in one line."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
import torch

from rllib_asor.algorithms.escp.module import CONTEXT
from rllib_asor.algorithms.osi.config import OsiConfig
from rllib_asor.algorithms.osi.network import OsiNetwork, osi_loss
from rllib_asor.algorithms.osi.replay import PARAMS
from rllib_asor.algorithms.osi.settings import OsiSettings


class GainEnv(gym.Env):
    """A user's env: x moves by gain·a; the gain (one of three) is the hidden dynamics,
    reported as `info["dynamics_params"]` (and its task as `dynamics_id`)."""

    GAINS = (-1.0, 0.5, 2.0)
    observation_space = gym.spaces.Box(-10, 10, (2,), np.float32)
    action_space = gym.spaces.Box(-1, 1, (1,), np.float32)

    def __init__(self, config=None) -> None:
        self._rng = np.random.default_rng(0)

    def _info(self) -> dict:
        return {"dynamics_id": self.task, "dynamics_params": np.array([self.GAINS[self.task] / 2])}

    def reset(self, *, seed=None, options=None):
        self.task, self.x, self.t = int(self._rng.integers(3)), 1.0, 0
        return np.array([self.x, 0.0], np.float32), self._info()

    def step(self, action):
        self.x = float(np.clip(self.x + self.GAINS[self.task] * float(action[0]) * 0.2, -10, 10))
        self.t += 1
        obs = np.array([self.x, self.t / 20], np.float32)
        return obs, -abs(self.x), False, self.t >= 20, self._info()


def _config() -> OsiConfig:
    return (
        OsiConfig()
        .environment(GainEnv)
        .env_runners(num_env_runners=0)
        .osi(history_len=4, param_dim=1, osi_hidden=[32, 32])
        .training(num_steps_sampled_before_learning_starts=64, train_batch_size_per_learner=32)
        .reporting(min_sample_timesteps_per_iteration=64)
        .debugging(seed=0)
    )


def _module(algo):
    return algo.learner_group._learner.module["default_policy"].unwrapped()


def _osi_error(module, batch) -> float:
    """OSI's squared error of the true parameters on `batch` (its windows)."""
    from rllib_asor.algorithms.escp.replay import WINDOW

    with torch.no_grad():
        return osi_loss(module.context(batch[WINDOW]), batch[PARAMS].float()).item()


def test_osi_loss_is_the_mean_squared_error_of_the_estimate():
    assert osi_loss(torch.tensor([[1.0, 2.0]]), torch.zeros(1, 2)).item() == pytest.approx(2.5)
    assert osi_loss(torch.tensor([[0.3, -0.2]]), torch.tensor([[0.3, -0.2]])).item() == 0.0
    twice = osi_loss(torch.tensor([[2.0, 4.0]]), torch.zeros(1, 2)).item()
    assert twice == pytest.approx(4 * 2.5)  # quadratic in the error
    pred = torch.zeros(4, 1, requires_grad=True)
    osi_loss(pred, torch.ones(4, 1)).backward()  # the gradient pulls the estimate up
    assert torch.all(pred.grad < 0)


def test_osi_network_reads_the_flattened_window_and_refuses_other_shapes():
    net = OsiNetwork(history_len=10, step_dim=3, param_dim=2)
    assert [m.out_features for m in net.net if isinstance(m, torch.nn.Linear)] == [256, 128, 64, 2]
    assert net(torch.zeros(5, 10, 3)).shape == (5, 2)
    with pytest.raises(ValueError, match=r"expects a \[B, 10, 3\] window, got \(5, 9, 3\)"):
        net(torch.zeros(5, 9, 3))


def test_the_shift_env_reports_its_parameters_scaled_to_plus_minus_one():
    env = gym.make("rllib_asor/Walker2dShift-v0", num_tasks=4)
    _, info = env.reset(seed=0)
    u = env.unwrapped
    assert u.param_names == ("mass", "damping", "wind_x", "wind_y")
    p, d = info["dynamics_params"], info["dynamics"]
    assert p.dtype == np.float32 and p.shape == (4,) and np.all(np.abs(p) <= 1)
    assert p[0] == pytest.approx(math.log(d["mass"], 1.5) / 3, rel=1e-5)
    assert p[2:] == pytest.approx(np.asarray(d["wind"]) / 3, rel=1e-5)
    _, _, _, _, info = env.step(env.action_space.sample())
    assert np.array_equal(info["dynamics_params"], p)
    fixed = gym.make("rllib_asor/HopperShift-v0", dynamics="body_mass")
    assert fixed.reset(seed=0)[1]["dynamics_params"].shape == (0,)


@pytest.mark.parametrize(
    ("settings", "match"),
    [
        ({"history_len": 0}, r"^osi.history_len=0 is not allowed; expected an int ≥ 1$"),
        ({"osi_lr": 0}, r"^osi.osi_lr=0 is not allowed; expected a number > 0$"),
        (
            {"histroy_len": 3},
            r"^osi.histroy_len is not an OSI setting \(did you mean 'history_len'\?\)",
        ),
    ],
)
def test_bad_settings_name_the_key_the_value_and_what_is_allowed(settings, match):
    with pytest.raises(ValueError, match=match):
        OsiSettings.from_dict(settings)
    with pytest.raises(ValueError, match=match):
        OsiConfig().osi(**settings)


def test_osi_trains_on_a_users_env_policy_on_true_parameters_osi_by_regression(ray_session):
    algo = _config().build_algo()
    try:
        algo.train()
        module = _module(algo)
        assert isinstance(module.encoder, OsiNetwork)
        before = {k: v.clone() for k, v in module.state_dict().items()}
        batch = algo.local_replay_buffer.sample(256)[0].columns
        batch = {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in batch.items()}
        first = _osi_error(module, batch)
        losses = [algo.train()["learners"]["default_policy"]["osi_loss"] for _ in range(6)]
        after = module.state_dict()
        for prefix in ("encoder.", "pi.", "qf."):
            assert any(not torch.equal(before[k], after[k]) for k in after if k.startswith(prefix))
        assert all(math.isfinite(x) for x in losses)
        assert _osi_error(module, batch) < 0.75 * first  # OSI learns to identify the gain
        # the universal policy reads the true parameters: no RL gradient reaches OSI
        assert set(np.round(batch[PARAMS].numpy().ravel(), 3)) <= {-0.5, 0.25, 1.0}
        fwd = module.forward_train(batch)
        module.zero_grad(set_to_none=True)
        (fwd["q_curr"].mean() + fwd["qf_preds"].mean()).backward()
        assert all(p.grad is None for p in module.encoder.parameters())
        assert fwd[CONTEXT].requires_grad
        ckpt = algo.save_to_path()
        weights = {k: v.clone() for k, v in module.state_dict().items()}
    finally:
        algo.stop()
    from ray.rllib.algorithms.algorithm import Algorithm

    restored = Algorithm.from_checkpoint(ckpt)
    try:
        state = _module(restored).state_dict()
        assert all(torch.equal(state[k], v) for k, v in weights.items())
        assert restored.train()["learners"]["default_policy"]["osi_loss"] >= 0
    finally:
        restored.stop()


def test_osi_with_asor_keeps_osis_losses_and_adds_the_bonus(ray_session):
    import rllib_asor
    from rllib_asor.algorithms.osi.learner import OsiLearnerMixin
    from rllib_asor.rllib.learners import AsorESCPTorchLearner

    algo = rllib_asor.with_asor(_config(), seed=0).build_algo()
    try:
        learner = algo.learner_group._learner
        assert isinstance(learner, OsiLearnerMixin) and isinstance(learner, AsorESCPTorchLearner)
        for _ in range(2):
            result = algo.train()
        stats = result["learners"]["default_policy"]
        assert math.isfinite(stats["osi_loss"]) and math.isfinite(stats["qf_loss"])
        assert "asor" in result
        ckpt = algo.save_to_path()
    finally:
        algo.stop()
    from ray.rllib.algorithms.algorithm import Algorithm

    restored = Algorithm.from_checkpoint(ckpt)
    try:
        assert isinstance(restored.learner_group._learner, OsiLearnerMixin)
        assert math.isfinite(restored.train()["learners"]["default_policy"]["osi_loss"])
    finally:
        restored.stop()
