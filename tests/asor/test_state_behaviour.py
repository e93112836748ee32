"""ASOR's state through `asor_update` on hand-made batches: the discriminator learns
a separable batch, every piece of state survives a round trip by name and value (auto-λ
among the cases), the archive is filled within the call that ends an episode."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from rllib_asor.asor.archive import discounted_return_to_go
from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.discriminator import discriminator_loss
from rllib_asor.asor.proxy import ProxyInputs, make_proxy
from rllib_asor.asor.update import AsorBatch, AsorState, Chunk, asor_update

DIM = 3


def episodes(seed: int, n_eps: int = 6, length: int = 8, terminated: bool = True) -> AsorBatch:
    """n_eps episodes; the odd ones pay 1 at the end and live in the +2 cluster of features,
    the even ones pay nothing and live in the −2 cluster (a separable batch)."""
    g = torch.Generator().manual_seed(seed)
    n = n_eps * length
    feats, rewards = torch.empty(n, DIM), torch.full((n,), -0.02)
    terms = torch.zeros(n, dtype=torch.bool)
    chunks = []
    for e in range(n_eps):
        rows = slice(e * length, (e + 1) * length)
        feats[rows] = torch.randn(length, DIM, generator=g) * 0.3 + (2.0 if e % 2 else -2.0)
        rewards[(e + 1) * length - 1] = 1.0 if e % 2 else 0.0
        terms[(e + 1) * length - 1] = terminated
        chunks.append(Chunk(("ep", seed, e), e * length, (e + 1) * length, dynamics_id=e % 3))
    values = torch.cat([discounted_return_to_go(rewards[c.start : c.stop], 0.9) for c in chunks])
    actions = torch.randn(n, 2, generator=g)
    next_feats = feats + 0.1 * actions.sum(-1, keepdim=True)
    return AsorBatch(
        features=feats,
        env_rewards=rewards,
        values=values,
        gamma=0.9,
        timestep=float(seed * n),
        proxy_inputs=ProxyInputs(feats, actions, next_feats, torch.arange(n) % 3),
        next_features=next_feats,
        terminateds=terms,
        next_values=torch.cat([values[1:], torch.zeros(1)]),
        chunks=chunks,
    )


def train_step(cfg: AsorConfig, state: AsorState, proxy, result, batch, opts) -> dict:
    """One gradient step of the discriminator and the proxy, as the Learner takes them."""
    logits = state.disc(result.disc_features)
    loss, stats = discriminator_loss(logits, result.disc_labels, cfg.label_smoothing)
    real = result.disc_features[result.disc_labels > 0.5]
    reg, _ = state.disc.regularizer(real, cfg.disc_grad_penalty, cfg.disc_logit_reg)
    total = loss + reg
    if proxy is not None:
        total = total + proxy.loss(batch.proxy_inputs)
    for opt in opts:
        opt.zero_grad()
    total.backward()
    for opt in opts:
        opt.step()
    return stats


def build(cfg: AsorConfig):
    torch.manual_seed(0)
    state = AsorState(cfg, DIM)
    proxy = make_proxy(cfg, DIM, 2, seed=1) if cfg.needs_proxy else None
    params = [p for p in state.parameters() if p.requires_grad]
    if proxy is not None:
        params += [p for p in proxy.parameters() if p.requires_grad]
    return state, proxy, [torch.optim.Adam(params, lr=1e-2)]


# ------------------------------------------------------------------ the discriminator learns
@pytest.mark.parametrize("preset", ["paper", "robust"])
def test_discriminator_weights_change_and_accuracy_rises_on_a_separable_batch(preset):
    # D_P and D_Q from the batch (the archive's D_Q, the whole batch, is not separable)
    cfg = AsorConfig(preset=preset, mode="srpo", seed=0, disc_hiddens=[16, 16], real_source="batch")
    state, proxy, opts = build(cfg)
    rng = np.random.default_rng(0)
    before = {k: v.clone() for k, v in state.disc.state_dict().items()}
    accuracies = []
    for i in range(40):
        batch = episodes(i % 4)
        result = asor_update(cfg, state, proxy, batch, rng)
        # D_P is the high-value cluster: the batch is separable by its features.
        real = result.disc_features[result.disc_labels > 0.5]
        assert len(real) > 0 and (real.mean(-1) > 0).all()
        stats = train_step(cfg, state, proxy, result, batch, opts)
        accuracies.append(0.5 * float(stats["disc_acc_real"] + stats["disc_acc_fake"]))
    changed = [k for k, v in state.disc.net.state_dict().items() if not torch.equal(v, before["net." + k])]
    assert len(changed) == len(before) - (3 if preset == "robust" else 0)  # every weight moved
    assert accuracies[0] < 0.9 and min(accuracies[-5:]) > 0.9
    with torch.no_grad():
        logits = state.disc(episodes(99).features)
    # ω is high on the real cluster and low on the other, bonus follows
    good = episodes(99).features.mean(-1) > 0
    assert logits[good].min() > 0 > logits[~good].max()


# ------------------------------------------------------------------ checkpoint round trip
CASES = {
    "robust_auto_lambda_per_dynamics": dict(
        lambda_="auto", lambda_init=0.3, lambda_lr=0.5, lambda_target=0.0,
        bonus_norm="running", proxy="rnd_per_dynamics", dynamics_buckets=4,
    ),
    "robust_rnd": dict(proxy="rnd", bonus_norm="running"),
    "paper_ensemble_schedule": dict(
        preset="paper", proxy="ensemble", lambda_=[[0, 0.0], [1000, 0.5]],
        disc_input_norm=True, bonus_norm="running",
    ),
    "robust_auto_lambda_srpo": dict(mode="srpo", lambda_="auto", lambda_init=0.2, lambda_kp=1.0),
}


def pieces(state: AsorState, proxy) -> dict[str, torch.Tensor]:
    """Every piece of ASOR's state by attribute (not through state_dict, whose key set a
    missing piece would leave out on both sides)."""
    out = {f"disc.{k}": v for k, v in state.disc.net.named_parameters()}
    if state.disc.input_rms is not None:
        out |= {f"disc.input_rms.{k}": getattr(state.disc.input_rms, k) for k in ("mean", "var", "count")}
    for name in ("bonus_rms", "reward_rms"):
        out |= {f"{name}.{k}": getattr(getattr(state, name), k) for k in ("mean", "var", "count")}
    if state.archive is not None:
        a = state.archive
        for k in ("features", "returns", "return_to_go", "stamp", "size", "episodes_added"):
            out[f"archive.{k}"] = getattr(a, k)
    out["auto_lambda"] = state.auto_lambda
    out["critic_ready"] = state.critic_ready
    if proxy is not None:
        inner = getattr(proxy, "rnd", None) or proxy.ensemble
        out |= {f"proxy.{k}": v for k, v in inner.named_parameters()}
        for rms in ("obs_rms", "delta_rms"):
            if hasattr(inner, rms):
                out |= {f"proxy.{rms}.{k}": getattr(getattr(inner, rms), k) for k in ("mean", "var", "count")}
        if hasattr(inner, "seen"):
            out["proxy.seen"] = inner.seen
    return {k: v.detach().clone() for k, v in out.items()}


@pytest.mark.parametrize("case", sorted(CASES))
def test_every_piece_of_state_survives_a_round_trip_by_name_and_value(case):
    cfg = AsorConfig(seed=0, disc_hiddens=[16], rnd_hiddens=[16], rnd_embedding_dim=8, **CASES[case])
    state, proxy, opts = build(cfg)
    fresh = pieces(state, proxy)
    rng = np.random.default_rng(0)
    for i in range(4):
        batch = episodes(i)
        result = asor_update(cfg, state, proxy, batch, rng)
        train_step(cfg, state, proxy, result, batch, opts)
    saved = pieces(state, proxy)
    # The pieces that this configuration moves did move (else the comparison proves nothing).
    moved = {k for k in saved if not torch.equal(saved[k], fresh[k])}
    expect_moved = {"auto_lambda"} if cfg.lambda_ == "auto" else set()
    expect_moved |= {"reward_rms.mean", "reward_rms.count", "disc.0.weight", "disc.2.bias"}
    if cfg.lambda_warmup:
        expect_moved |= {"critic_ready"}
    if cfg.bonus_norm == "running":
        expect_moved |= {"bonus_rms.mean", "bonus_rms.var", "bonus_rms.count"}
    if cfg.disc_input_norm:
        expect_moved |= {"disc.input_rms.mean", "disc.input_rms.count"}
    if state.archive is not None:
        expect_moved |= {f"archive.{k}" for k in ("features", "returns", "return_to_go", "stamp", "size", "episodes_added")}
    if proxy is not None:
        expect_moved |= {k for k in saved if k.startswith("proxy.obs_rms")}
        if cfg.proxy == "rnd_per_dynamics":
            expect_moved |= {"proxy.seen"}
    assert expect_moved <= moved, expect_moved - moved

    # Round trip through state_dict into freshly built objects with other initial weights.
    torch.manual_seed(123)
    state2 = AsorState(cfg, DIM)
    proxy2 = make_proxy(cfg, DIM, 2, seed=7) if proxy is not None else None
    state2.load_state_dict(state.state_dict())
    if proxy is not None:
        proxy2.load_state_dict(proxy.state_dict())
    restored = pieces(state2, proxy2)
    assert restored.keys() == saved.keys()
    for name, value in saved.items():
        assert torch.equal(restored[name], value), name

    # And the next update is the same on the original and on the restored copy.
    batch = episodes(10)
    a = asor_update(cfg, state, proxy, batch, np.random.default_rng(5))
    b = asor_update(cfg, state2, proxy2, episodes(10), np.random.default_rng(5))
    assert torch.equal(a.reward_delta, b.reward_delta)
    assert torch.equal(a.disc_labels, b.disc_labels)
    assert a.metrics["lambda"] == b.metrics["lambda"]


def test_auto_lambda_integral_is_carried_from_batch_to_batch():
    cfg = AsorConfig(lambda_="auto", lambda_lr=0.5, lambda_target=0.0, mode="srpo", seed=0,
                     lambda_warmup=False, bonus_share_max=0.0, lambda_relative=False)
    state, proxy, opts = build(cfg)
    rng = np.random.default_rng(0)
    lams = []
    for i in range(12):
        batch = episodes(i % 4)
        result = asor_update(cfg, state, proxy, batch, rng)
        train_step(cfg, state, proxy, result, batch, opts)
        lams.append(result.metrics["lambda"])
    # the JS estimate exceeds ε = 0 once the discriminator separates: λ climbs from 0
    assert lams[0] == 0.0 and lams[-1] > lams[5] > 0.0
    assert float(state.auto_lambda) > 0.0


# ------------------------------------------------------------------ the archive
def test_archive_is_filled_within_the_update_that_ends_an_episode():
    cfg = AsorConfig(seed=0, mode="srpo", disc_hiddens=[8])
    state = AsorState(cfg, DIM)
    rng = np.random.default_rng(0)
    open_batch = episodes(0, terminated=False)
    asor_update(cfg, state, None, open_batch, rng)
    assert len(state.archive) == 0 and state.archive.open_episodes == 6

    # The episodes end (terminated) in the next call: archived in that same call, and its
    # states are the discriminator's real samples already.
    closing = episodes(0, n_eps=6, length=2)
    result = asor_update(cfg, state, None, closing, rng)
    assert state.archive.open_episodes == 0
    assert len(state.archive) == 6 * (8 + 2)
    assert state.archive.bucket_sizes()[:3] == [20, 20, 20]
    real = result.disc_features[result.disc_labels > 0.5]
    assert len(real) > 0
    stored = torch.cat([state.archive.features[b, : int(state.archive.size[b])] for b in range(3)])
    assert all((stored == row).all(-1).any() for row in real)
    assert result.metrics["archive_states"] == 60.0


def test_an_episode_that_stops_arriving_is_archived_in_the_next_call():
    cfg = AsorConfig(seed=0, mode="srpo", disc_hiddens=[8])
    state = AsorState(cfg, DIM)
    rng = np.random.default_rng(0)
    asor_update(cfg, state, None, episodes(0, terminated=False), rng)
    assert len(state.archive) == 0
    asor_update(cfg, state, None, episodes(1, terminated=False), rng)  # other episodes
    assert len(state.archive) == 48 and state.archive.open_episodes == 6
