"""CaDM (model-free variant): its loss on hand-made tensors (sign and scale), the context
network's gradient from both models, training on a user's env from Python (π reads the context
without gradient), with ASOR, its checkpoint round trip, and bad settings in one line."""

from __future__ import annotations

import copy
import math

import gymnasium as gym
import numpy as np
import pytest
import torch

from rllib_asor.algorithms.cadm.config import CadmConfig
from rllib_asor.algorithms.cadm.model import CadmModel, cadm_loss
from rllib_asor.algorithms.cadm.settings import CadmSettings
from rllib_asor.algorithms.escp.module import CONTEXT


class GainEnv(gym.Env):
    """A user's env: x moves by gain·a; the gain (one of three) is the hidden dynamics."""

    GAINS = (-1.0, 0.5, 2.0)
    observation_space = gym.spaces.Box(-10, 10, (2,), np.float32)
    action_space = gym.spaces.Box(-1, 1, (1,), np.float32)

    def __init__(self, config=None) -> None:
        self._rng = np.random.default_rng(0)

    def reset(self, *, seed=None, options=None):
        self.task, self.x, self.t = int(self._rng.integers(3)), 1.0, 0
        return np.array([self.x, 0.0], np.float32), {"dynamics_id": self.task}

    def step(self, action):
        self.x = float(np.clip(self.x + self.GAINS[self.task] * float(action[0]) * 0.2, -10, 10))
        self.t += 1
        obs = np.array([self.x, self.t / 20], np.float32)
        return obs, -abs(self.x), False, self.t >= 20, {"dynamics_id": self.task}


def _config() -> CadmConfig:
    return (
        CadmConfig()
        .environment(GainEnv)
        .env_runners(num_env_runners=0)
        .cadm(history_len=4, context_hidden=[32], model_hidden=[32, 32])
        .training(num_steps_sampled_before_learning_starts=64, train_batch_size_per_learner=32)
        .reporting(min_sample_timesteps_per_iteration=64)
        .debugging(seed=0)
    )


def _module(algo):
    return algo.learner_group._learner.module["default_policy"].unwrapped()


def _model_loss(module, batch) -> float:
    """CaDM's loss (forward Gaussian NLL + backward error) on `batch` with the windows'
    contexts."""
    from ray.rllib.core.columns import Columns

    from rllib_asor.algorithms.escp.replay import WINDOW

    with torch.no_grad():
        obs, act, nxt = batch[Columns.OBS], batch[Columns.ACTIONS], batch[Columns.NEXT_OBS]
        c = module.context(batch[WINDOW])
        mu, logvar = module.encoder.predict_forward(obs, act, c)
        back = module.encoder.predict_backward(nxt, act, c)
        return float(cadm_loss(mu, logvar, nxt - obs, back, obs - nxt)[0])


def test_cadm_loss_sign_and_scale_on_hand_made_tensors():
    zero = torch.zeros(4, 3)
    # perfect predictions with unit variance: nothing to pay
    loss, parts = cadm_loss(zero, zero, zero, zero, zero, back_coeff=0.5)
    assert loss.item() == 0.0 and parts["cadm_forward_mse"].item() == 0.0
    # forward error 1 everywhere at log variance 0: 1; at log variance log 2: 1/2 + log 2
    ones = torch.ones(4, 3)
    assert cadm_loss(ones, zero, zero, zero, zero)[0].item() == pytest.approx(1.0)
    half = cadm_loss(ones, torch.full((4, 3), math.log(2)), zero, zero, zero)[0].item()
    assert half == pytest.approx(0.5 + math.log(2))
    # backward error 2 everywhere costs back_coeff · 4
    assert cadm_loss(zero, zero, zero, 2 * ones, zero, back_coeff=0.5)[0].item() == pytest.approx(
        2.0
    )
    assert cadm_loss(zero, zero, zero, 2 * ones, zero, back_coeff=0.0)[0].item() == 0.0
    # the variance bounds are regularised: 0.01 · (Σ max − Σ min)
    reg = cadm_loss(
        zero, zero, zero, zero, zero, 0.5, torch.full((3,), 0.5), torch.full((3,), -10.0)
    )
    assert reg[0].item() == pytest.approx(0.01 * (1.5 + 30.0))


def test_both_models_train_the_context_network():
    model = CadmModel(obs_dim=2, act_dim=1, history_len=4, context_dim=3)
    window = torch.randn(8, 4, 3)
    obs, act, nxt = torch.randn(8, 2), torch.randn(8, 1), torch.randn(8, 2)
    for which in ("forward", "backward"):
        model.zero_grad(set_to_none=True)
        c = model(window)
        if which == "forward":
            mu, logvar = model.predict_forward(obs, act, c)
            loss = cadm_loss(mu, logvar, nxt - obs, torch.zeros_like(obs), torch.zeros_like(obs))[0]
        else:
            loss = (model.predict_backward(nxt, act, c) - (obs - nxt)).pow(2).mean()
        loss.backward()
        assert all(
            p.grad is not None and p.grad.abs().sum() > 0 for p in model.context_net.parameters()
        )
    mu, logvar = model.predict_forward(obs, act, model(window))
    assert torch.all(logvar <= model.max_logvar + 1e-6) and torch.all(
        logvar >= model.min_logvar - 1e-6
    )
    with pytest.raises(ValueError, match=r"expects a \[B, 4, 3\] window, got \(8, 5, 3\)"):
        model(torch.zeros(8, 5, 3))


@pytest.mark.parametrize(
    ("settings", "match"),
    [
        ({"back_coeff": -1}, r"^cadm.back_coeff=-1 is not allowed; expected a number ≥ 0$"),
        ({"context_dim": 0}, r"^cadm.context_dim=0 is not allowed; expected an int ≥ 1$"),
        (
            {"backcoeff": 1},
            r"^cadm.backcoeff is not a CaDM setting \(did you mean 'back_coeff'\?\)",
        ),
    ],
)
def test_bad_settings_name_the_key_the_value_and_what_is_allowed(settings, match):
    with pytest.raises(ValueError, match=match):
        CadmSettings.from_dict(settings)
    with pytest.raises(ValueError, match=match):
        CadmConfig().cadm(**settings)


def test_cadm_trains_on_a_users_env_and_its_checkpoint_round_trips(ray_session):
    algo = _config().build_algo()
    try:
        untrained = copy.deepcopy(_module(algo))
        algo.train()
        module = _module(algo)
        assert isinstance(module.encoder, CadmModel)
        before = {k: v.clone() for k, v in module.state_dict().items()}
        batch = algo.local_replay_buffer.sample(256)[0].columns
        batch = {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in batch.items()}
        stats = [algo.train()["learners"]["default_policy"] for _ in range(6)]
        after = module.state_dict()
        for prefix in ("encoder.context_net.", "encoder.forward_model.", "pi.", "qf."):
            assert any(not torch.equal(before[k], after[k]) for k in after if k.startswith(prefix))
        assert all(math.isfinite(s["cadm_loss"]) for s in stats)
        # the models learn these transitions: against the same module untrained (the loss on a
        # fixed batch moves by about 1 from one iteration to the next, so not against iteration 1)
        assert _model_loss(module, batch) < _model_loss(untrained, batch) - 1.0
        # π and the critics read the context without gradient
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
        assert math.isfinite(restored.train()["learners"]["default_policy"]["cadm_loss"])
    finally:
        restored.stop()


def test_cadm_with_asor_keeps_cadms_loss_and_adds_the_bonus(ray_session):
    import rllib_asor
    from rllib_asor.algorithms.cadm.learner import CadmLearnerMixin

    algo = rllib_asor.with_asor(_config(), seed=0).build_algo()
    try:
        assert isinstance(algo.learner_group._learner, CadmLearnerMixin)
        assert isinstance(_module(algo).encoder, CadmModel)
        for _ in range(2):
            result = algo.train()
        assert math.isfinite(result["learners"]["default_policy"]["cadm_loss"])
        assert "asor" in result
    finally:
        algo.stop()
