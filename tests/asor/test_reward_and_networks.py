"""Reward bonus, λ, discriminator loss, RND and ensemble on hand-made tensors."""

import math

import numpy as np
import pytest
import torch

from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.discriminator import Discriminator, discriminator_loss
from rllib_asor.asor.networks import RunningMeanStd
from rllib_asor.asor.proxy import RND, DynamicsEnsemble
from rllib_asor.asor.reward import dual_ascent_step, reward_bonus, scheduled_lambda

EXTREME = torch.tensor([-1e30, -1e4, -50.0, -1.0, 0.0, 1.0, 50.0, 1e4, 1e30])


@pytest.mark.parametrize("form", ["log", "centered", "gail"])
def test_extreme_logits_give_finite_bonus(form):
    bonus = reward_bonus(EXTREME, form, log_omega_min=-5.0)
    assert torch.isfinite(bonus).all()


def test_log_form_is_clipped_log_sigmoid():
    bonus = reward_bonus(EXTREME, "log", -5.0)
    assert bonus.min().item() == -5.0 and bonus.max().item() <= 0.0
    assert bonus[4].item() == pytest.approx(math.log(0.5))


def test_centered_form_has_zero_mean():
    assert reward_bonus(EXTREME, "centered", -5.0).mean().item() == pytest.approx(0.0, abs=1e-6)


def test_gail_form_is_non_negative_and_bounded():
    bonus = reward_bonus(EXTREME, "gail", -5.0)
    assert bonus.min().item() >= 0.0 and bonus.max().item() == 5.0
    assert bonus[4].item() == pytest.approx(math.log(2.0))


def test_nan_logits_raise():
    with pytest.raises(ValueError, match="NaN"):
        reward_bonus(torch.tensor([0.0, float("nan")]))


def test_lambda_schedule_interpolates_and_holds_ends():
    spec = [[0, 0.0], [100, 1.0], [200, 0.5]]
    assert scheduled_lambda(spec, -5) == 0.0
    assert scheduled_lambda(spec, 50) == pytest.approx(0.5)
    assert scheduled_lambda(spec, 150) == pytest.approx(0.75)
    assert scheduled_lambda(spec, 1e9) == 0.5
    assert scheduled_lambda(0.3, 1e9) == 0.3


def test_dual_ascent_moves_towards_constraint_and_clips():
    assert dual_ascent_step(0.1, js_estimate=0.5, target=0.1, lr=0.1, lam_max=1.0) == pytest.approx(
        0.14
    )
    assert dual_ascent_step(0.01, js_estimate=0.0, target=0.1, lr=1.0, lam_max=1.0) == 0.0
    assert dual_ascent_step(0.9, js_estimate=0.69, target=0.0, lr=1.0, lam_max=1.0) == 1.0


def test_discriminator_loss_statistics():
    logits = torch.tensor([10.0, 10.0, -10.0, -10.0])
    labels = torch.tensor([1.0, 1.0, 0.0, 0.0])
    loss, stats = discriminator_loss(logits, labels)
    assert loss.item() < 1e-3
    assert stats["disc_acc_real"].item() == 1.0 and stats["disc_acc_fake"].item() == 1.0
    assert stats["js_estimate"].item() == pytest.approx(math.log(2.0), abs=1e-3)
    _, chance = discriminator_loss(torch.zeros(4), labels)
    assert chance["js_estimate"].item() == pytest.approx(0.0, abs=1e-6)


def test_label_smoothing_keeps_loss_above_zero_on_perfect_logits():
    logits = torch.tensor([20.0, -20.0])
    labels = torch.tensor([1.0, 0.0])
    assert discriminator_loss(logits, labels, label_smoothing=0.1)[0].item() > 1.0


def test_discriminator_learns_to_separate():
    torch.manual_seed(0)
    disc = Discriminator(2, [32, 32])
    opt = torch.optim.Adam(disc.parameters(), lr=1e-2)
    x = torch.cat([torch.randn(64, 2) + 2.0, torch.randn(64, 2) - 2.0])
    y = torch.cat([torch.ones(64), torch.zeros(64)])
    for _ in range(100):
        loss, stats = discriminator_loss(disc(x), y)
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert stats["disc_acc_real"].item() > 0.95 and stats["disc_acc_fake"].item() > 0.95


def test_running_mean_std_matches_numpy():
    rms = RunningMeanStd(3)
    data = np.random.default_rng(0).normal(2.0, 3.0, size=(1000, 3))
    for chunk in np.split(data, 10):
        rms.update(torch.tensor(chunk))
    assert np.allclose(rms.mean.numpy(), data.mean(0), atol=1e-3)
    assert np.allclose(rms.var.numpy(), data.var(0), rtol=1e-2)


def test_rnd_error_falls_on_seen_states_only():
    torch.manual_seed(0)
    rnd = RND(4, [64, 64], 16, seed=0)
    seen = torch.randn(256, 4)
    unseen = torch.randn(256, 4) + 4.0
    rnd.update_normalizer(torch.cat([seen, unseen]))
    opt = torch.optim.Adam([p for p in rnd.parameters() if p.requires_grad], lr=1e-3)
    before = rnd.prediction_error(seen).mean().item()
    for _ in range(300):
        loss = rnd.prediction_error(seen).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert rnd.prediction_error(seen).mean().item() < 0.2 * before
    assert rnd.count_proxy(seen).mean() > rnd.count_proxy(unseen).mean()
    assert not any(p.requires_grad for p in rnd.target.parameters())


def test_ensemble_disagrees_more_off_distribution():
    torch.manual_seed(0)
    ens = DynamicsEnsemble(obs_dim=3, action_dim=2, size=5, hiddens=[64])
    obs = torch.randn(512, 3)
    act = torch.randn(512, 2)
    nxt = obs + 0.1 * act.sum(-1, keepdim=True)
    ens.update_normalizers(obs, nxt)
    opt = torch.optim.Adam(ens.parameters(), lr=3e-3)
    for _ in range(300):
        loss = ens.loss(obs, act, nxt)
        opt.zero_grad()
        loss.backward()
        opt.step()
    far_obs = torch.randn(512, 3) * 4 + 8
    assert ens.disagreement(obs, act).mean() < ens.disagreement(far_obs, act).mean()


@pytest.mark.parametrize(
    "settings, key",
    [
        ({"rho_value": 1.5}, "rho_value"),
        ({"rho_count": 0}, "rho_count"),
        ({"lambda_": -0.1}, "lambda_"),
        ({"lambda": "sometimes"}, "lambda_"),
        ({"lambda_": [[10, 0.1], [5, 0.2]]}, "lambda_"),
        ({"mode": "gan"}, "mode"),
        ({"proxy": "counts"}, "proxy"),
        ({"reward_form": "exp"}, "reward_form"),
        ({"log_omega_min": 1.0}, "log_omega_min"),
        ({"disc_hiddens": []}, "disc_hiddens"),
        ({"rhos": 0.5}, "unknown key"),
    ],
)
def test_config_errors_name_key_and_allowed(settings, key):
    with pytest.raises(ValueError, match=key) as err:
        AsorConfig.from_dict(settings)
    assert "allowed" in str(err.value)


def test_config_accepts_lambda_alias_schedule_and_auto():
    assert AsorConfig.from_dict({"lambda": 0.2}).lambda_ == 0.2
    assert AsorConfig.from_dict({"lambda_": [[0, 0], [1000, 0.1]]}).lambda_ == [
        [0.0, 0.0],
        [1000.0, 0.1],
    ]
    assert AsorConfig.from_dict({"lambda_": "auto"}).lambda_ == "auto"
    assert AsorConfig(mode="srpo", rho_value=0.5, rho_count=0.2).effective_rhos == (0.5, 1.0)


def test_per_dynamics_rnd_counts_states_seen_under_every_dynamics_higher():
    from rllib_asor.asor.proxy import PerDynamicsRND

    torch.manual_seed(0)
    rnd = PerDynamicsRND(4, [64, 64], 16, buckets=4, seed=0)
    shared = torch.randn(128, 4)  # visited under dynamics 0 and 1
    only_0 = torch.randn(128, 4) + 3.0  # visited under dynamics 0 only
    x = torch.cat([shared, only_0, shared])
    ids = torch.cat([torch.zeros(256), torch.ones(128)]).long()
    rnd.update(x, ids)
    opt = torch.optim.Adam([p for p in rnd.parameters() if p.requires_grad], lr=1e-3)
    for _ in range(300):
        loss = rnd.prediction_error(x, ids).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert rnd.seen.tolist() == [1.0, 1.0, 0.0, 0.0]
    assert rnd.count_proxy(shared).mean() > rnd.count_proxy(only_0).mean()
