"""The batched probabilistic ensemble: forward, loss, training with holdout, elites, cache."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from rllib_asor.algorithms.maple.ensemble import (
    GaussianEnsemble,
    cache_path,
    choose_elites,
    dataset_key,
    gaussian_nll,
    load_ensemble,
    looped_forward,
    save_ensemble,
    train_ensemble,
    validation_mse,
)


def _linear_data(n: int = 600, seed: int = 0) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    obs = rng.normal(size=(n, 3)).astype(np.float32)
    act = rng.uniform(-1, 1, size=(n, 2)).astype(np.float32)
    nxt = obs + 0.1 * np.concatenate([act, act[:, :1]], axis=1)
    rew = obs[:, 0] - act[:, 1]
    return obs, act, nxt, rew


def test_batched_forward_equals_the_per_member_loop() -> None:
    torch.manual_seed(0)
    model = GaussianEnsemble(3, 2, members=4, elites=2, hidden=16)
    obs, act = torch.randn(10, 3), torch.randn(10, 2)
    mu, logstd = model(obs, act)
    mu_l, logstd_l = looped_forward(model, obs, act)
    assert mu.shape == (4, 10, 4) and logstd.shape == (4, 10, 4)
    torch.testing.assert_close(mu, mu_l)
    torch.testing.assert_close(logstd, logstd_l)
    # the elites alone: the same as the full forward's elite members
    model.elite_idx.copy_(torch.tensor([3, 1]))
    mu_e, logstd_e = model.elites(obs, act)
    torch.testing.assert_close(mu_e, mu[[3, 1]])
    torch.testing.assert_close(logstd_e, logstd[[3, 1]])
    # each member its own rows ([K, N, ·] inputs)
    obs_k, act_k = torch.randn(4, 10, 3), torch.randn(4, 10, 2)
    mu_k, _ = model(obs_k, act_k)
    for k in range(4):
        torch.testing.assert_close(mu_k[k], model(obs_k[k], act_k[k])[0][k])


def test_mean_is_a_residual_on_the_state_and_logstd_stays_in_the_learned_bounds() -> None:
    model = GaussianEnsemble(3, 2, members=2, elites=1, hidden=8)
    with torch.no_grad():
        model.out.weight.zero_()
        model.out.bias.zero_()
        model.out.bias[:, 0, 4:] = 50.0  # log σ far above the upper bound
    obs = torch.tensor([[1.0, 2.0, 3.0]])
    mu, logstd = model(obs, torch.zeros(1, 2))
    torch.testing.assert_close(mu[0, 0, :3], obs[0])  # s + Δ with Δ = 0
    assert mu[0, 0, 3].item() == 0.0  # reward: direct
    # soft clamp (the port's): at most softplus(max − min) − (max − min) ≈ 0.0025 above the bound
    assert (logstd <= model.max_logstd + 0.01).all() and (logstd >= model.min_logstd).all()
    assert logstd.max().item() > 0.99


def test_gaussian_nll_is_the_summed_negative_log_likelihood_plus_the_bound_term() -> None:
    model = GaussianEnsemble(1, 1, members=2, elites=1, hidden=4)
    mu = torch.tensor([[[0.0, 1.0]], [[2.0, 0.0]]])
    logstd = torch.tensor([[[0.0, math.log(2.0)]], [[0.0, 0.0]]])
    target = torch.tensor([[1.0, 1.0]])
    expected = 0.0
    for m, s, t in ((0.0, 1.0, 1.0), (1.0, 2.0, 1.0), (2.0, 1.0, 1.0), (0.0, 1.0, 1.0)):
        expected += 0.5 * ((t - m) / s) ** 2 + math.log(s) + 0.5 * math.log(2 * math.pi)
    expected += 0.01 * 2 * (1.0 + 1.0) - 0.01 * 2 * (-5.0 - 5.0)  # bounds init 1 and −5
    got = gaussian_nll(mu, logstd, target.expand(2, 1, 2), model)
    assert got.item() == pytest.approx(expected, rel=1e-5)


def test_elites_are_the_members_with_the_lowest_validation_loss() -> None:
    assert choose_elites([0.3, 0.1, 0.2, 0.5, 0.1], 3) == [1, 4, 2]


def test_training_learns_stops_early_and_keeps_each_members_best_weights(tmp_path) -> None:
    torch.manual_seed(0)
    obs, act, nxt, rew = _linear_data()
    model = GaussianEnsemble(3, 2, members=3, elites=2, hidden=32)
    before = validation_mse(
        model,
        torch.as_tensor(obs),
        torch.as_tensor(act),
        torch.as_tensor(np.concatenate([nxt, rew[:, None]], 1)),
    )
    report = train_ensemble(
        model, obs, act, nxt, rew, seed=0, batch_size=64, patience=2, max_epochs=200
    )
    assert report.holdout_rows == min(int(600 * 0.2) + 1, 1000)
    assert report.stopped_early and report.epochs < 200
    assert max(report.val_losses) < 0.2 * before.min().item()
    # the kept weights are each member's best epoch: the holdout MSE is its minimum over epochs
    hist = np.array(report.history)
    np.testing.assert_allclose(report.val_losses, hist.min(0), rtol=1e-6)
    assert report.elites == choose_elites(report.val_losses, 2)
    assert model.elite_idx.tolist() == report.elites
    # cache round trip: the same predictions, keyed by seed
    path = cache_path(tmp_path, "abc", seed=3)
    assert path != cache_path(tmp_path, "abc", seed=4)
    save_ensemble(model, report, path)
    loaded, rep = load_ensemble(path)
    x, a = torch.randn(5, 3), torch.randn(5, 2)
    torch.testing.assert_close(loaded.elites(x, a)[0], model.elites(x, a)[0])
    assert rep["elites"] == report.elites


def test_cache_key_follows_the_rows_not_the_path(tmp_path) -> None:
    """A copied or freshly cloned dataset (new path, new mtimes) finds its ensemble; other
    rows or other ensemble settings do not."""
    import shutil

    a = tmp_path / "a" / "medium"
    a.mkdir(parents=True)
    (a / "part-0.parquet").write_bytes(b"rows of the first build")
    b = tmp_path / "copy" / "medium"
    shutil.copytree(a, b)
    settings = {"ensemble_members": 7}
    key = dataset_key([str(a)], settings)
    assert dataset_key([str(b)], settings) == key
    assert dataset_key([str(a)], {"ensemble_members": 5}) != key
    (b / "part-0.parquet").write_bytes(b"rows of another build")
    assert dataset_key([str(b)], settings) != key


def test_bad_elite_count_is_refused() -> None:
    with pytest.raises(ValueError, match="elites=8"):
        GaussianEnsemble(3, 2, members=7, elites=8)
