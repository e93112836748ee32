"""Model rollouts: the uncertainty penalty, termination, the clip range, one member per path."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from rllib_asor.algorithms.maple import termination
from rllib_asor.algorithms.maple.ensemble import GaussianEnsemble
from rllib_asor.algorithms.maple.rollout import (
    ClipRange,
    clip_range,
    model_rollout,
    penalized_reward,
    uncertainty,
)
from rllib_asor.algorithms.maple.termination import hopper, termination_fn


def test_uncertainty_is_the_largest_members_std_norm_and_the_penalty_is_clipped() -> None:
    logstd = torch.log(torch.tensor([[[3.0, 4.0]], [[1.0, 1.0]]]))  # ‖σ‖ = 5 and √2
    assert uncertainty(logstd).tolist() == pytest.approx([5.0])
    r, u = penalized_reward(torch.tensor([1.0]), logstd, coef=0.25, clip=40.0)
    assert r.item() == pytest.approx(1.0 - 0.25 * 5.0) and u.item() == pytest.approx(5.0)
    r, u = penalized_reward(torch.tensor([1.0]), logstd, coef=0.25, clip=2.0)
    assert r.item() == pytest.approx(1.0 - 0.25 * 2.0) and u.item() == pytest.approx(2.0)


def test_clip_range_is_the_data_range_widened_and_floored() -> None:
    obs = np.array([[0.0, -1.0], [1.0, 3.0]])
    rng = clip_range(obs, np.array([0.5, 2.0]), penalty_coef=0.25, penalty_clip=40, floor=0)
    np.testing.assert_allclose(rng.obs_lo, [-0.05, -1.2])
    np.testing.assert_allclose(rng.obs_hi, [1.05, 3.2])
    assert rng.rew_lo == pytest.approx(0.5 - 10.0) and rng.rew_hi == 2.0
    floored = clip_range(obs, np.array([0.5, 2.0]), 0.25, 40)  # the port: at least ±100
    np.testing.assert_allclose(floored.obs_hi, [100, 100])


def test_hopper_termination_rule() -> None:
    ok = np.array([[1.2, 0.0, 1.0]])
    assert not hopper(ok)[0]
    assert hopper(np.array([[0.7, 0.0, 0.0]]))[0]  # too low
    assert hopper(np.array([[1.2, 0.25, 0.0]]))[0]  # tilted
    assert hopper(np.array([[1.2, 0.0, -150.0]]))[0]  # out of range
    assert hopper(np.array([[np.nan, 0.0, 0.0]]))[0]
    assert termination_fn("rllib_asor/HopperShift-v0") is hopper
    with pytest.raises(ValueError, match="env='CartPole-v1'.*hopper.*register_termination"):
        termination_fn("CartPole-v1")


def test_a_users_env_gets_its_registered_termination_rule(monkeypatch) -> None:
    monkeypatch.setattr(termination, "RULES", dict(termination.RULES))
    never = lambda o: np.zeros(len(o), bool)  # noqa: E731
    termination.register_termination("MySlip", never)
    assert termination_fn("me/MySlipWorld-v0") is never
    assert termination_fn("rllib_asor/HopperShift-v0") is hopper
    with pytest.raises(ValueError, match="key='' is invalid"):
        termination.register_termination("", never)


def _hand_made_ensemble(drifts: list[float], log_sigma: float = -12.0) -> GaussianEnsemble:
    """Members whose μ = s + (−0.12, 0, drift_k) and reward 1, σ ≈ e^log_sigma."""
    model = GaussianEnsemble(3, 1, members=len(drifts), elites=len(drifts), hidden=4)
    with torch.no_grad():
        model.min_logstd.fill_(-20.0)
        model.max_logstd.fill_(10.0)  # the soft clamp leaves σ as set
        model.out.weight.zero_()
        model.out.bias.zero_()
        for k, d in enumerate(drifts):
            model.out.bias[k, 0, :4] = torch.tensor([-0.12, 0.0, d, 1.0])
        model.out.bias[:, 0, 4:] = log_sigma
    return model


def _starts(n: int) -> dict[str, np.ndarray]:
    return {
        "obs": np.tile(np.array([[1.0, 0.0, 0.0]], np.float32), (n, 1)),
        "last_actions": np.zeros((n, 1), np.float32),
        "policy_hidden": np.zeros((n, 2), np.float32),
        "value_hidden": np.zeros((n, 2), np.float32),
    }


def _zero_policy(obs, last, hidden):
    return torch.zeros(obs.shape[0], 1), hidden + 1.0


def test_rollouts_stop_at_termination_and_stay_in_the_clip_range() -> None:
    model = _hand_made_ensemble([0.0, 0.0])
    limits = ClipRange(
        obs_lo=np.array([-5.0, -5.0, -5.0], np.float32),
        obs_hi=np.array([5.0, 5.0, 5.0], np.float32),
        rew_lo=-10.0,
        rew_hi=10.0,
    )
    seg, stats = model_rollout(
        model, _zero_policy, _starts(4), 6, hopper, limits, 0.0, 40.0, np.random.default_rng(0)
    )
    # height 1.0 → 0.88 → 0.76 → 0.64: the third step ends the episode (height must stay > 0.7)
    assert seg["valid"].tolist() == [[True] * 3 + [False] * 3] * 4
    assert seg["terminateds"][:, 2].all() and not seg["terminateds"][:, :2].any()
    assert (seg["obs"][:, 3:] == 0).all()  # steps after the end are not computed
    np.testing.assert_allclose(seg["obs"][0, :3, 0], [1.0, 0.88, 0.76], atol=1e-4)
    np.testing.assert_allclose(seg["next_obs"][:, :, :], seg["next_obs"].clip(-5, 5))
    assert stats.valid_fraction == pytest.approx(0.5)
    assert seg["obs"].shape == (4, 6, 3) and seg["rewards"].shape == (4, 6)


def test_next_states_never_leave_the_clip_range_and_one_member_drives_each_path() -> None:
    drifts = [0.5, -0.3, 0.05]
    model = _hand_made_ensemble(drifts)
    limits = ClipRange(
        obs_lo=np.array([-100, -1, -1.0], np.float32),
        obs_hi=np.array([100, 1, 1.0], np.float32),
        rew_lo=-10.0,
        rew_hi=10.0,
    )
    halfcheetah_like = lambda nxt: np.zeros(len(nxt), bool)  # noqa: E731
    seg, _ = model_rollout(
        model,
        _zero_policy,
        _starts(60),
        5,
        halfcheetah_like,
        limits,
        0.0,
        40.0,
        np.random.default_rng(1),
        chunk=16,
    )
    assert (seg["next_obs"] >= limits.obs_lo - 1e-6).all()
    assert (seg["next_obs"] <= limits.obs_hi + 1e-6).all()
    first = seg["next_obs"][:, 0, 2]  # the drift of the member that made step 1
    member = np.array([int(np.argmin(np.abs(np.array(drifts) - f))) for f in first])
    assert len(set(member.tolist())) == 3  # all members are used
    for i, k in enumerate(member):  # the same member throughout (until the clip binds)
        expect = np.clip(np.cumsum([drifts[k]] * 5), -1, 1)
        np.testing.assert_allclose(seg["next_obs"][i, :, 2], expect, atol=1e-4)
    # hidden states and last actions are threaded through: a_{t-1} of step t is step t-1's action
    np.testing.assert_allclose(seg["last_actions"][:, 1:], seg["actions"][:, :-1])


def test_rewards_are_clipped_then_penalised() -> None:
    model = _hand_made_ensemble([0.0], log_sigma=math.log(0.5))  # ‖σ‖ = 0.5·√4 = 1
    limits = ClipRange(np.full(3, -5, np.float32), np.full(3, 5, np.float32), -10.0, 0.8)
    never = lambda nxt: np.zeros(len(nxt), bool)  # noqa: E731
    seg, stats = model_rollout(
        model, _zero_policy, _starts(2000), 1, never, limits, 0.25, 40.0, np.random.default_rng(0)
    )
    assert stats.uncertainty_mean == pytest.approx(1.0, rel=1e-4)
    assert seg["rewards"].max() <= 0.8 - 0.25 + 1e-5  # r ~ N(1, 0.5) clipped at 0.8, minus λu
