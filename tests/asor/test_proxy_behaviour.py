"""The visitation proxies on hand-set networks: the RND error does not depend on an
affine change of the features once the normaliser has seen them, the per-dynamics count follows
its rule (the least familiar dynamics seen so far), the ensemble's disagreement is exact."""

from __future__ import annotations

import pytest
import torch

from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.proxy import (
    RND,
    DynamicsEnsemble,
    EnsembleProxy,
    PerDynamicsRND,
    PerDynamicsRndProxy,
    ProxyInputs,
    RndProxy,
    make_proxy,
)


def data(n=512, dim=3, seed=0):
    return torch.randn(n, dim, generator=torch.Generator().manual_seed(seed)) * 0.5 + 1.0


def offset_predictor(pred: torch.nn.Sequential, target: torch.nn.Sequential, offset: float) -> None:
    """predictor := target with `offset` added to every output: its error is offset² exactly."""
    with torch.no_grad():
        for p, t in zip(pred.parameters(), target.parameters(), strict=True):
            p.copy_(t)
        pred[-1].bias.add_(offset)


# ------------------------------------------------------------------ RND
@pytest.mark.parametrize("scale, shift", [(10.0, -3.0), (0.1, 0.5), (1.0, 0.0)])
def test_rnd_error_is_unchanged_by_an_affine_change_of_the_features(scale, shift):
    x = data()
    a, b = RND(3, [16], 8, seed=0), RND(3, [16], 8, seed=0)
    a.update_normalizer(x)
    moved = x * torch.tensor([scale, 2 * scale, 0.5 * scale]) + shift
    b.update_normalizer(moved)
    ea, eb = a.prediction_error(x), b.prediction_error(moved)
    assert ea.shape == (512,) and torch.allclose(ea, eb, rtol=1e-3, atol=1e-6)
    assert torch.allclose(a.count_proxy(x), -ea.detach())
    # without the normaliser's statistics the raw features give another error
    if scale != 1.0:
        c = RND(3, [16], 8, seed=0)
        assert not torch.allclose(c.prediction_error(x), c.prediction_error(moved), rtol=1e-2)


def test_rnd_error_is_the_mean_squared_output_difference():
    rnd = RND(2, [8], 4, seed=0)
    offset_predictor(rnd.predictor, rnd.target, 0.5)
    x = data(dim=2)
    assert torch.allclose(rnd.prediction_error(x), torch.full((512,), 0.25), atol=1e-6)
    assert torch.allclose(RndProxy(rnd).count(ProxyInputs(x)), torch.full((512,), -0.25), atol=1e-6)
    # the inputs are clipped to ±5 standard deviations
    rnd.update_normalizer(x)
    far = torch.full((1, 2), 1e6)
    edge = (rnd.obs_rms.mean + 5.0 * torch.sqrt(rnd.obs_rms.var + 1e-8)).reshape(1, 2)
    assert torch.allclose(rnd.target(rnd.obs_rms.normalize(far)), rnd.target(rnd.obs_rms.normalize(edge)))


def test_seeded_rnd_is_reproducible_and_leaves_the_global_stream_alone():
    torch.manual_seed(1)
    a = RND(3, [8], 4, seed=7)
    after_a = torch.rand(3)
    torch.manual_seed(2)
    b = PerDynamicsRND(3, [8], 4, buckets=2, seed=7)
    torch.manual_seed(1)
    assert torch.equal(torch.rand(3), after_a)  # building `a` drew nothing from the global RNG
    for pa, pb in zip(a.target.parameters(), b.target.parameters(), strict=True):
        assert torch.equal(pa, pb)
    assert torch.equal(a.predictor[0].weight, b.predictors[0][0].weight)
    assert not torch.equal(b.predictors[0][0].weight, b.predictors[1][0].weight)
    torch.manual_seed(1)
    c, d = RND(3, [8], 4), RND(3, [8], 4)  # unseeded: the global stream, two different nets
    assert not torch.equal(c.target[0].weight, d.target[0].weight)
    assert not any(p.requires_grad for p in a.target.parameters())
    assert all(p.requires_grad for p in a.predictor.parameters())


# ------------------------------------------------------------------ per-dynamics RND
def hand_set(offsets):
    rnd = PerDynamicsRND(2, [8], 4, buckets=len(offsets), seed=0)
    for pred, off in zip(rnd.predictors, offsets, strict=True):
        offset_predictor(pred, rnd.target, off)
    return rnd


def test_per_dynamics_count_is_minus_the_largest_error_over_the_dynamics_seen():
    rnd = hand_set([0.1, 0.2, 0.3, 0.4])  # errors 0.01, 0.04, 0.09, 0.16
    x = data(8, dim=2)
    # nothing seen yet: the mean over every predictor
    assert torch.allclose(rnd.count_proxy(x), torch.full((8,), -0.075), atol=1e-6)
    proxy = PerDynamicsRndProxy(rnd)
    proxy.observe(ProxyInputs(x, dynamics_ids=torch.tensor([0, 4, 0, 4, 0, 4, 0, 4])))  # 4 ≡ 0
    assert rnd.seen.tolist() == [1.0, 0.0, 0.0, 0.0]
    assert torch.allclose(proxy.count(ProxyInputs(x)), torch.full((8,), -0.01), atol=1e-6)
    proxy.observe(ProxyInputs(x, dynamics_ids=torch.tensor([1, 2, 1, 2, 1, 2, 1, -3])))  # -3 ≡ 1
    assert rnd.seen.tolist() == [1.0, 1.0, 1.0, 0.0]
    assert torch.allclose(proxy.count(ProxyInputs(x)), torch.full((8,), -0.09), atol=1e-6)
    # the training loss: each state's error under its own dynamics' predictor
    ids = torch.tensor([0, 1, 2, 3, 4, 5, 6, 7])
    expected = torch.tensor([0.01, 0.04, 0.09, 0.16] * 2)
    assert rnd.prediction_error(x, ids).shape == (8,)
    assert torch.allclose(rnd.prediction_error(x, ids), expected, atol=1e-6)
    assert proxy.loss(ProxyInputs(x, dynamics_ids=ids)).item() == pytest.approx(0.075, abs=1e-6)
    assert rnd.errors(x).shape == (4, 8)


def test_per_dynamics_rnd_needs_dynamics_ids():
    proxy = PerDynamicsRndProxy(hand_set([0.1, 0.2]))
    with pytest.raises(ValueError, match="dynamics_ids"):
        proxy.observe(ProxyInputs(data(4, dim=2)))


def test_per_dynamics_error_is_unchanged_by_an_affine_change_once_seen():
    x, ids = data(256, dim=2), torch.arange(256) % 2
    a, b = hand_set([0.0, 0.0]), hand_set([0.0, 0.0])
    for rnd in (a, b):  # a trained predictor 1 (non-zero error everywhere else)
        with torch.no_grad():
            rnd.predictors[1][0].weight.mul_(1.5)
    moved = x * 7.0 - 2.0
    a.update(x, ids)
    b.update(moved, ids)
    assert torch.allclose(a.errors(x), b.errors(moved), rtol=1e-3, atol=1e-6)
    assert a.errors(x)[1].mean() > 0


# ------------------------------------------------------------------ ensemble
def test_ensemble_disagreement_is_the_largest_distance_to_the_mean_prediction():
    ens = DynamicsEnsemble(obs_dim=2, action_dim=1, size=3, hiddens=[4])
    with torch.no_grad():  # model k predicts the constant vector (k, 0) (normalised units)
        for k, m in enumerate(ens.models):
            for p in m.parameters():
                p.zero_()
            m[-1].bias.copy_(torch.tensor([float(k), 0.0]))
    obs, act = data(5, dim=2), torch.ones(5, 1)
    assert ens.predictions(obs, act).shape == (3, 5, 2)
    assert torch.allclose(ens.disagreement(obs, act), torch.full((5,), 1.0))  # mean 1: |0-1|, |2-1|
    proxy = EnsembleProxy(ens)
    assert torch.allclose(proxy.count(ProxyInputs(obs, act)), torch.full((5,), -1.0))
    # the loss: Σ_k mean‖μ_k − normalised Δ‖², Δ = s′ − s normalised by the running statistics
    nxt = obs + 3.0
    proxy.observe(ProxyInputs(obs, act, nxt))
    assert torch.allclose(ens.delta_rms.mean, torch.full((2,), 3.0), atol=1e-3)
    target = ens.delta_rms.normalize(nxt - obs)  # ≈ 0: the deltas are constant
    expected = sum(((torch.tensor([float(k), 0.0]) - target) ** 2).mean() for k in range(3))
    assert proxy.loss(ProxyInputs(obs, act, nxt)).item() == pytest.approx(float(expected), rel=1e-4)
    with pytest.raises(ValueError, match="next_features"):
        proxy.observe(ProxyInputs(obs, act))
    with pytest.raises(ValueError, match="actions"):
        proxy.count(ProxyInputs(obs))


def test_ensemble_normalises_its_inputs():
    a = DynamicsEnsemble(obs_dim=2, action_dim=1, size=2, hiddens=[8])
    b = DynamicsEnsemble(obs_dim=2, action_dim=1, size=2, hiddens=[8])
    b.load_state_dict(a.state_dict())
    obs, act = data(64, dim=2), torch.randn(64, 1)
    a.update_normalizers(obs, obs + 1.0)
    b.update_normalizers(obs * 4.0 + 1.0, obs * 4.0 + 2.0)
    assert torch.allclose(a.predictions(obs, act), b.predictions(obs * 4.0 + 1.0, act), atol=1e-5)


# ------------------------------------------------------------------ make_proxy
@pytest.mark.parametrize("name, cls", [("rnd", RndProxy), ("rnd_per_dynamics", PerDynamicsRndProxy),
                                       ("ensemble", EnsembleProxy)])
def test_make_proxy_builds_the_named_proxy_from_the_settings(name, cls):
    cfg = AsorConfig(proxy=name, rnd_hiddens=[8, 4], rnd_embedding_dim=5, dynamics_buckets=3,
                     ensemble_size=4)
    proxy = make_proxy(cfg, feature_dim=6, action_dim=2, seed=0)
    assert isinstance(proxy, cls) and proxy.name == name
    if name == "rnd":
        assert proxy.rnd.target[-1].out_features == 5 and proxy.rnd.predictor[0].in_features == 6
    elif name == "rnd_per_dynamics":
        assert proxy.rnd.buckets == 3 and proxy.rnd.target[-1].out_features == 5
    else:
        assert len(proxy.ensemble.models) == 4 and proxy.ensemble.models[0][0].in_features == 8
    hidden = [m.out_features for m in next(iter(proxy.modules())).modules()
              if isinstance(m, torch.nn.Linear)][:2]
    assert hidden == [8, 4]
    again = make_proxy(cfg, feature_dim=6, action_dim=2, seed=0)
    if name != "ensemble":  # the seed fixes RND's networks
        for pa, pb in zip(proxy.parameters(), again.parameters(), strict=True):
            assert torch.equal(pa, pb)


def test_per_dynamics_count_before_any_dynamics_is_seen_averages_the_predictors():
    rnd = PerDynamicsRND(3, [8], 4, buckets=3, seed=0)
    x = torch.randn(5, 3, generator=torch.Generator().manual_seed(0))
    errors = rnd.errors(x)
    counts = rnd.count_proxy(x)
    assert counts.shape == (5,) and torch.allclose(counts, -errors.mean(0))
