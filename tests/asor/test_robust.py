"""The robust default's pieces on hand-made arrays: bonus form and scaling, gradient penalty,
archive insert/evict/checkpoint, λ warm-up, potential shaping, presets."""

import numpy as np
import pytest
import torch

from rllib_asor.asor.archive import StateArchive, discounted_return_to_go
from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.discriminator import Discriminator
from rllib_asor.asor.networks import RunningMeanStd
from rllib_asor.asor.reward import (
    explained_variance,
    potential_shaping,
    reward_bonus,
    reward_scale,
    standardize,
)
from rllib_asor.asor.update import AsorBatch, AsorState, Chunk, asor_update


# ------------------------------------------------------------------ presets
def test_presets_fill_only_the_fields_left_open():
    robust, paper = AsorConfig(), AsorConfig(preset="paper")
    assert (robust.reward_form, robust.real_source, robust.lambda_relative) == ("logit", "archive", True)
    assert (paper.reward_form, paper.real_source, paper.lambda_) == ("log", "batch", 0.01)
    assert AsorConfig(preset="paper", reward_form="gail").reward_form == "gail"
    assert AsorConfig.from_dict(AsorConfig(preset="paper").to_dict()) == paper


def test_unknown_preset_and_typo_say_what_is_allowed():
    with pytest.raises(ValueError, match="preset.*robust \\| paper"):
        AsorConfig(preset="fast")
    with pytest.raises(ValueError, match="did you mean 'lambda_'"):
        AsorConfig.from_dict({"lamda_": 0.1})


# ------------------------------------------------------------------ bonus form and scale
def test_logit_form_is_two_signed_and_bounded():
    logits = torch.tensor([-50.0, -1.0, 0.0, 2.0, 50.0])
    b = reward_bonus(logits, "logit", logit_clip=5.0)
    assert b.tolist() == [-5.0, -1.0, 0.0, 2.0, 5.0]


def test_standardised_bonus_is_centred_and_clipped():
    b = torch.tensor([0.0, 1.0, 2.0, 3.0, 100.0])
    z = standardize(b, b.mean(), b.var(unbiased=False), clip=1.5)
    assert z.abs().max() <= 1.5 and z[0] < 0 < z[-1]


@pytest.mark.parametrize("norm", ["running", "batch"])
def test_bonus_norms_keep_the_bound_and_batch_norm_centres_each_batch(norm):
    cfg = AsorConfig(mode="srpo", bonus_norm=norm, shaping="direct")
    state, results = _run(cfg, 1.0)
    delta = results[-1].reward_delta
    lam = results[-1].metrics["lambda"]
    assert delta.abs().max() <= lam * cfg.bonus_clip + 1e-6
    if norm == "batch":
        assert abs(delta.mean().item()) <= 0.1 * lam  # ≈ zero mean (clipping aside)


@pytest.mark.parametrize("scale", [1.0, 100.0])
def test_reward_scale_is_the_running_rms(scale):
    rms = RunningMeanStd(1)
    rms.update(torch.full((1000, 1), scale))  # a constant reward (CartPole)
    assert reward_scale(rms) == pytest.approx(scale, rel=1e-3)


def test_potential_shaping_drops_the_next_state_after_termination():
    b, nb = torch.tensor([1.0, 2.0]), torch.tensor([3.0, 4.0])
    f = potential_shaping(b, nb, torch.tensor([False, True]), gamma=0.5)
    assert f.tolist() == [0.5 * 3.0 - 1.0, -2.0]


def test_explained_variance_of_perfect_and_constant_values():
    t = torch.tensor([1.0, 2.0, 3.0])
    assert explained_variance(t, t) == pytest.approx(1.0)
    assert explained_variance(torch.zeros(3), torch.ones(3)) == -1.0


# ------------------------------------------------------------------ discriminator
def test_gradient_penalty_of_a_linear_discriminator_is_its_weight_norm():
    disc = Discriminator(3, hiddens=[])
    with torch.no_grad():
        disc.net[0].weight.copy_(torch.tensor([[1.0, 2.0, -2.0]]))
    loss, stats = disc.regularizer(torch.randn(7, 3), grad_penalty=5.0, logit_reg=0.0)
    assert stats["disc_grad_penalty"].item() == pytest.approx(9.0)
    assert loss.item() == pytest.approx(45.0)
    loss.backward()
    assert disc.net[0].weight.grad.abs().sum() > 0  # the penalty trains the weights


def test_input_normalisation_makes_logits_invariant_to_feature_scale():
    torch.manual_seed(0)
    disc = Discriminator(2, hiddens=[8], input_norm=True)
    x = torch.randn(256, 2)
    disc.observe(x)
    big = Discriminator(2, hiddens=[8], input_norm=True)
    big.load_state_dict(disc.state_dict())
    big.input_rms.mean.mul_(1000.0)
    big.input_rms.var.mul_(1000.0**2)
    assert torch.allclose(disc(x), big(x * 1000.0), atol=1e-4)


# ------------------------------------------------------------------ archive
def test_archive_keeps_the_best_episodes_and_prefers_the_newest_among_equals():
    arch = StateArchive(feature_dim=1, capacity=4, buckets=2)
    for ret, value in ((1.0, 10.0), (5.0, 50.0), (1.0, 11.0)):
        arch.insert(torch.full((2, 1), value), torch.zeros(2), ret, dynamics_id=0)
    kept = sorted(arch.features[0, : int(arch.size[0]), 0].tolist())
    assert kept == [11.0, 11.0, 50.0, 50.0]  # the return-5 episode, then the newer return-1 one
    arch.insert(torch.ones(3, 1), torch.zeros(3), 0.0, dynamics_id=3)  # bucket 1
    assert arch.bucket_sizes() == [4, 3]
    feats, _ = arch.sample(4, torch.Generator().manual_seed(0))
    assert (feats == 1.0).sum() == 2  # even over the buckets


def test_archive_joins_chunks_and_closes_episodes_that_stop_arriving():
    arch = StateArchive(feature_dim=1, capacity=10, buckets=1)
    arch.add_chunk("a", torch.zeros(2, 1), torch.tensor([0.0, 1.0]), 0, terminated=False, gamma=0.5)
    arch.end_call(0.5)
    assert len(arch) == 0 and arch.open_episodes == 1
    arch.add_chunk("a", torch.zeros(1, 1), torch.tensor([2.0]), 0, terminated=True, gamma=0.5)
    assert len(arch) == 0  # archived with the call's other episodes, at its end
    arch.end_call(0.5)
    assert len(arch) == 3 and arch.returns[0, 0] == 3.0 and arch.open_episodes == 0
    assert sorted(arch.return_to_go[0, :3].tolist()) == [1.0, 2.0, 2.0]
    arch.add_chunk("b", torch.zeros(1, 1), torch.tensor([1.0]), 0, terminated=False, gamma=0.5)
    arch.end_call(0.5)
    assert len(arch) == 3 and arch.open_episodes == 1
    arch.end_call(0.5)  # "b" got no chunk in this call: the env truncated it
    assert len(arch) == 4 and arch.open_episodes == 0


def test_inserting_a_calls_episodes_together_keeps_what_one_by_one_keeps():
    g = torch.Generator().manual_seed(0)
    episodes = [
        (torch.randn(int(n), 2, generator=g), torch.randn(int(n), generator=g), float(r), int(d))
        for n, r, d in zip(torch.randint(1, 6, (30,), generator=g),
                           torch.randint(0, 4, (30,), generator=g), torch.arange(30) % 3,
                           strict=True)
    ]  # fmt: skip
    one, many = (StateArchive(feature_dim=2, capacity=7, buckets=2) for _ in range(2))
    for ep in episodes[:10]:  # some states already there, as after earlier calls
        one.insert(*ep)
        many.insert(*ep)
    for ep in episodes[10:]:
        one.insert(*ep)
    many.insert_many(episodes[10:])
    for (name, a), b in zip(one.state_dict().items(), many.state_dict().values(), strict=True):
        assert torch.equal(a, b), name


def test_archive_survives_a_state_dict_round_trip():
    arch = StateArchive(feature_dim=2, capacity=3, buckets=2)
    arch.insert(torch.randn(2, 2), torch.ones(2), 1.0, dynamics_id=1)
    other = StateArchive(feature_dim=2, capacity=3, buckets=2)
    other.load_state_dict(arch.state_dict())
    assert other.bucket_sizes() == [0, 2] and torch.equal(other.features, arch.features)


def test_discounted_return_to_go():
    assert discounted_return_to_go(torch.tensor([1.0, 0.0, 2.0]), 0.5).tolist() == [1.5, 1.0, 2.0]
    assert discounted_return_to_go(torch.zeros(0), 0.99).shape == (0,)
    rewards = torch.randn(500, generator=torch.Generator().manual_seed(0))
    expected, running = torch.empty(500), 0.0
    for t in range(499, -1, -1):  # the recurrence G_t = r_t + γ G_{t+1}, in float64
        running = float(rewards[t]) + 0.99 * running
        expected[t] = running
    got = discounted_return_to_go(rewards, 0.99)
    assert got.dtype == torch.float32 and torch.equal(got, expected)


def test_return_to_go_of_episodes_back_to_back_restarts_at_each_episode():
    assert discounted_return_to_go(torch.tensor([1.0, 2.0, 4.0]), 0.5, [2, 1]).tolist() == [
        2.0, 2.0, 4.0,  # [1 + 0.5·2, 2] then [4]: nothing carried over from the next episode
    ]  # fmt: skip
    rewards = torch.randn(500, generator=torch.Generator().manual_seed(1))
    lengths = [1, 200, 99, 1, 199]
    one_by_one = torch.cat([discounted_return_to_go(r, 0.99) for r in rewards.split(lengths)])
    torch.testing.assert_close(discounted_return_to_go(rewards, 0.99, lengths), one_by_one)


def test_closing_many_episodes_in_one_call_keeps_what_one_by_one_inserts_keep():
    g = torch.Generator().manual_seed(0)
    together, one_by_one = StateArchive(2, capacity=30, buckets=3), StateArchive(2, capacity=30, buckets=3)
    for call in range(6):
        for i in range(7):
            n = 1 + (3 * i + call) % 9
            feats, rewards = torch.randn(n, 2, generator=g), torch.randn(n, generator=g).round()
            together.add_chunk((call, i), feats, rewards, i - 2, terminated=True, gamma=0.9)
            rtg = discounted_return_to_go(rewards, 0.9)
            one_by_one.insert(feats, rtg, float(rewards.sum()), i - 2)
        together.end_call(0.9)
    for name in ("features", "returns", "return_to_go", "stamp", "size", "episodes_added"):
        torch.testing.assert_close(getattr(together, name), getattr(one_by_one, name), msg=name)


# ------------------------------------------------------------------ the whole update
def _episodes_batch(reward_scale_factor: float, n_eps: int = 8, length: int = 10, seed: int = 0):
    """n_eps complete episodes; the goal pays at the end, better episodes come from one side."""
    g = torch.Generator().manual_seed(seed)
    feats = torch.randn(n_eps * length, 3, generator=g)
    rewards = torch.full((n_eps * length,), -0.02)
    terms = torch.zeros(n_eps * length, dtype=torch.bool)
    chunks = []
    for e in range(n_eps):
        end = (e + 1) * length - 1
        rewards[end] = 1.0 if e % 2 else 0.0
        terms[end] = True
        chunks.append(Chunk(("ep", e, seed), e * length, end + 1, dynamics_id=e % 4))
    rewards = rewards * reward_scale_factor
    # A critic that ranks states: the discounted returns themselves.
    values = torch.cat([discounted_return_to_go(rewards[c.start : c.stop], 0.99) for c in chunks])
    return AsorBatch(
        features=feats,
        env_rewards=rewards,
        values=values,
        gamma=0.99,
        terminateds=terms,
        next_values=torch.cat([values[1:], torch.zeros(1)]),
        next_features=torch.cat([feats[1:], feats[:1]]),
        chunks=chunks,
    )


def _run(cfg: AsorConfig, factor: float, batches: int = 4):
    state = AsorState(cfg, feature_dim=3)
    rng = np.random.default_rng(0)
    results = [asor_update(cfg, state, None, _episodes_batch(factor, seed=i), rng) for i in range(batches)]
    return state, results


def test_warm_up_adds_nothing_until_the_critic_ranks_states():
    cfg = AsorConfig(mode="srpo")
    state = AsorState(cfg, feature_dim=3)
    batch = _episodes_batch(1.0)
    batch.values = torch.zeros_like(batch.values)  # an untrained critic
    result = asor_update(cfg, state, None, batch, np.random.default_rng(0))
    assert result.metrics["active"] == 0.0 and torch.all(result.reward_delta == 0)
    _, results = _run(cfg, 1.0)
    assert results[-1].metrics["active"] == 1.0 and results[-1].reward_delta.abs().sum() > 0


def test_bonus_relative_to_reward_scale_is_the_same_at_100x_rewards():
    cfg = AsorConfig(mode="srpo", seed=0)
    torch.manual_seed(0)
    _, small = _run(cfg, 1.0)
    torch.manual_seed(0)
    _, big = _run(cfg, 100.0)
    share_small = small[-1].metrics["bonus_share"]
    share_big = big[-1].metrics["bonus_share"]
    assert share_small > 0 and 0.5 <= share_big / share_small <= 2.0
    assert torch.allclose(big[-1].reward_delta, 100.0 * small[-1].reward_delta, rtol=1e-3, atol=1e-5)


def test_constant_reward_gives_finite_bounded_bonuses():
    cfg = AsorConfig(mode="srpo")
    state = AsorState(cfg, feature_dim=3)
    rng = np.random.default_rng(0)
    for i in range(3):
        batch = _episodes_batch(1.0, seed=i)
        batch.env_rewards = torch.ones_like(batch.env_rewards)  # CartPole
        batch.values = torch.cat(
            [discounted_return_to_go(batch.env_rewards[c.start : c.stop], 0.99) for c in batch.chunks]
        )
        result = asor_update(cfg, state, None, batch, rng)
    assert result.metrics["reward_scale"] == pytest.approx(1.0, rel=1e-3)
    delta = result.reward_delta
    bound = cfg.lambda_ * (1 + 0.99) * cfg.bonus_clip  # |λ(γb′ − b)|, potential form
    assert torch.isfinite(delta).all() and delta.abs().max() <= bound + 1e-6


def test_paper_preset_is_the_log_penalty_on_the_batch_partition():
    cfg = AsorConfig(preset="paper", mode="srpo", lambda_=0.1)
    state = AsorState(cfg, feature_dim=3)
    batch = _episodes_batch(1.0)
    result = asor_update(cfg, state, None, batch, np.random.default_rng(0))
    with torch.no_grad():
        expected = 0.1 * reward_bonus(state.disc(batch.features), "log")
    assert torch.allclose(result.reward_delta, expected)
    assert result.disc_features.shape[0] == batch.features.shape[0]
    assert result.disc_labels.mean().item() == pytest.approx(0.5, abs=0.01)


def test_help_lists_every_setting_with_its_doc():
    import rllib_asor

    for doc in (AsorConfig.__doc__, rllib_asor.with_asor.__doc__):
        for name in ("preset", "lambda_", "real_source", "archive_size", "disc_grad_penalty"):
            assert f"    {name} = " in doc, name
    assert "paper 'log'" in AsorConfig.__doc__  # the paper preset's value beside the default


def test_batch_norm_keeps_the_bonus_share_when_the_discriminator_drifts():
    """The measured failure of `bonus_norm: running` (race/Hopper after 250k steps: potential
    share 3.5-5x below the lava world's): running statistics remember an earlier, wider logit
    distribution. Per-batch statistics do not."""

    def share_before_and_after_drift(norm: str) -> tuple[float, float]:
        cfg = AsorConfig(mode="srpo", bonus_norm=norm, seed=0)
        torch.manual_seed(0)
        state = AsorState(cfg, feature_dim=3)
        rng = np.random.default_rng(0)
        w0 = state.disc.net[-1].weight.data.clone()
        shares = []
        for i in range(60):  # a confident discriminator, then a much less confident one
            state.disc.net[-1].weight.data = w0 * (4.0 if i < 30 else 0.25)
            result = asor_update(cfg, state, None, _episodes_batch(1.0, seed=i), rng)
            shares.append(result.metrics["potential_share"])
        return shares[29], shares[-1]

    before, after = share_before_and_after_drift("batch")
    assert 0.5 <= after / before <= 2.0
    before, after = share_before_and_after_drift("running")
    assert after / before < 0.5


def test_bonus_share_cap_scales_lambda_down_only_when_exceeded():
    _, results = _run(AsorConfig(mode="srpo", lambda_=1.0, seed=0), 1.0)
    capped = results[-1].metrics
    assert capped["share_capped"] == 1.0
    assert capped["potential_share"] == pytest.approx(0.2, rel=1e-4)  # the robust preset's cap
    _, results = _run(AsorConfig(mode="srpo", seed=0), 1.0)  # λ 0.05: far below the cap
    assert results[-1].metrics["share_capped"] == 0.0
    assert 0 < results[-1].metrics["potential_share"] < 0.2
    _, results = _run(AsorConfig(mode="srpo", lambda_=1.0, bonus_share_max=0.0, seed=0), 1.0)
    assert results[-1].metrics["share_capped"] == 0.0 and results[-1].metrics["potential_share"] > 0.2


def test_auto_lambda_is_a_pi_lagrangian_on_the_js_estimate():
    from rllib_asor.asor.update import _lambda

    cfg = AsorConfig(lambda_="auto", lambda_lr=0.1, lambda_kp=2.0, lambda_target=0.1)
    state = AsorState(cfg, feature_dim=3)
    # Violation 0.2: the P term acts at once (2 × 0.2), the I term from the next batch on.
    assert _lambda(cfg, state, 0.3, 0.0) == pytest.approx(0.4)
    assert _lambda(cfg, state, 0.3, 0.0) == pytest.approx(0.02 + 0.4)
    # Satisfied (d̂ < ε): the P term pulls λ down, clipped at 0.
    assert _lambda(cfg, state, 0.0, 0.0) == pytest.approx(max(0.04 - 0.2, 0.0))
    pure = AsorConfig(lambda_="auto", lambda_lr=0.1, lambda_target=0.1)  # Kp 0: dual ascent
    state = AsorState(pure, feature_dim=3)
    assert [_lambda(pure, state, 0.3, 0.0) for _ in range(3)] == pytest.approx([0.0, 0.02, 0.04])
