"""Exact values of ASOR's small pieces on hand-made inputs (mutation survivors):
the discriminator's loss, statistics and regularisers, the archive's sampling, the partition's
random mode and sizes, the bonus standardisation and the logit bonus's clip."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from rllib_asor.asor.archive import StateArchive
from rllib_asor.asor.discriminator import Discriminator, discriminator_loss
from rllib_asor.asor.partition import partition, real_set_size
from rllib_asor.asor.reward import standardize


# ------------------------------------------------------------------ discriminator loss
def test_loss_is_the_class_balanced_mean_of_the_smoothed_bce():
    logits = torch.tensor([2.0, -1.0, 0.5, 3.0])
    labels = torch.tensor([1.0, 1.0, 1.0, 0.0])  # three real, one fake: balance matters
    eps = 0.1
    loss, stats = discriminator_loss(logits, labels, label_smoothing=eps)
    real_bce = F.binary_cross_entropy_with_logits(logits[:3], torch.full((3,), 1 - eps))
    fake_bce = F.binary_cross_entropy_with_logits(logits[3:], torch.full((1,), eps))
    assert loss.item() == pytest.approx(0.5 * (real_bce + fake_bce).item(), rel=1e-6)
    # the statistics use the unsmoothed labels
    raw_real = F.binary_cross_entropy_with_logits(logits[:3], torch.ones(3)).item()
    raw_fake = F.binary_cross_entropy_with_logits(logits[3:], torch.zeros(1)).item()
    assert stats["disc_bce_real"].item() == pytest.approx(raw_real, rel=1e-6)
    assert stats["disc_bce_fake"].item() == pytest.approx(raw_fake, rel=1e-6)
    assert stats["js_estimate"].item() == pytest.approx(math.log(2) - 0.5 * (raw_real + raw_fake), rel=1e-6)
    assert stats["disc_loss"].item() == pytest.approx(loss.item())
    assert stats["disc_acc_real"].item() == pytest.approx(2 / 3)
    assert stats["disc_acc_fake"].item() == 0.0


def test_accuracy_counts_only_the_right_side_of_zero_and_entropy_is_exact():
    logits = torch.tensor([0.0, 0.5, 0.0, -0.5])
    labels = torch.tensor([1.0, 1.0, 0.0, 0.0])
    _, stats = discriminator_loss(logits, labels)
    assert stats["disc_acc_real"].item() == 0.5 and stats["disc_acc_fake"].item() == 0.5
    p = torch.sigmoid(logits)
    entropy = -(p * p.log() + (1 - p) * (1 - p).log()).mean()
    assert stats["disc_entropy"].item() == pytest.approx(entropy.item(), rel=1e-6)
    _, stats = discriminator_loss(torch.zeros(2), torch.tensor([1.0, 0.0]))
    assert stats["disc_entropy"].item() == pytest.approx(math.log(2), rel=1e-6)
    _, empty = discriminator_loss(torch.zeros(0), torch.zeros(0))
    assert empty["disc_entropy"].item() == 0.0 and empty["disc_loss"].item() == 0.0


def test_one_sided_batch_has_no_nan():
    loss, stats = discriminator_loss(torch.tensor([1.0, 2.0]), torch.ones(2))
    assert torch.isfinite(loss) and stats["disc_acc_fake"].item() == 0.0
    assert stats["disc_bce_fake"].item() == 0.0


# ------------------------------------------------------------------ regularisers
def linear_disc(weight):
    disc = Discriminator(len(weight), hiddens=[])
    with torch.no_grad():
        disc.net[0].weight.copy_(torch.tensor([weight]))
    return disc


def test_logit_regulariser_is_the_squared_output_weights():
    disc = linear_disc([1.0, 2.0, -2.0])
    loss, stats = disc.regularizer(torch.randn(4, 3), grad_penalty=0.0, logit_reg=0.5)
    assert loss.item() == pytest.approx(0.5 * 9.0)
    assert stats["disc_grad_penalty"].item() == 0.0  # switched off: not computed
    assert stats["disc_logit_norm"].item() == pytest.approx(3.0)
    loss, _ = disc.regularizer(torch.randn(4, 3), grad_penalty=0.0, logit_reg=0.0)
    assert loss.item() == 0.0


def test_gradient_penalty_on_one_real_sample_and_none():
    disc = linear_disc([1.0, 2.0, -2.0])
    loss, stats = disc.regularizer(torch.randn(1, 3), grad_penalty=0.5, logit_reg=0.0)
    assert stats["disc_grad_penalty"].item() == pytest.approx(9.0)
    assert loss.item() == pytest.approx(4.5)
    loss, stats = disc.regularizer(torch.zeros(0, 3), grad_penalty=0.5, logit_reg=0.0)
    assert loss.item() == 0.0 and stats["disc_grad_penalty"].item() == 0.0


def test_gradient_penalty_is_taken_on_the_normalised_input():
    disc = Discriminator(2, hiddens=[], input_norm=True)
    with torch.no_grad():
        disc.net[0].weight.copy_(torch.tensor([[1.0, 1.0]]))
    disc.observe(torch.randn(4096, 2, generator=torch.Generator().manual_seed(0)) * 10.0)
    _, stats = disc.regularizer(torch.zeros(3, 2), grad_penalty=1.0, logit_reg=0.0)
    assert stats["disc_grad_penalty"].item() == pytest.approx(2.0)  # ∂/∂z of w·z, not of x


# ------------------------------------------------------------------ archive sampling
def test_sampling_an_empty_archive_or_nothing_gives_empty_tensors_of_the_feature_width():
    arch = StateArchive(feature_dim=4, capacity=3, buckets=2)
    feats, rtg = arch.sample(5)
    assert feats.shape == (0, 4) and rtg.shape == (0,)
    arch.insert(torch.ones(1, 4), torch.ones(1), 1.0, dynamics_id=1)
    feats, rtg = arch.sample(0)
    assert feats.shape == (0, 4) and rtg.shape == (0,)
    feats, rtg = arch.sample(5)  # one state in one bucket: drawn once, without replacement
    assert feats.shape == (1, 4) and rtg.tolist() == [1.0]


def test_sampling_follows_the_generator():
    arch = StateArchive(feature_dim=1, capacity=50, buckets=1)
    arch.insert(torch.arange(50.0).reshape(50, 1), torch.arange(50.0), 1.0, dynamics_id=0)
    a, _ = arch.sample(10, torch.Generator().manual_seed(3))
    b, _ = arch.sample(10, torch.Generator().manual_seed(3))
    c, _ = arch.sample(10, torch.Generator().manual_seed(4))
    assert torch.equal(a, b) and not torch.equal(a, c) and len(a.unique()) == 10


# ------------------------------------------------------------------ partition
def test_real_set_size_of_an_empty_and_a_small_batch():
    assert real_set_size(0, 0.5, 0.5) == 0
    assert real_set_size(10, 0.5, 0.5) == 3  # ⌈0.5·⌈0.5·10⌉⌉
    assert real_set_size(10, 0.5, 0.5, "srpo") == 5
    assert real_set_size(10, 0.5, 0.3, "count") == 3


def test_random_mode_follows_a_torch_generator():
    values = np.arange(20.0)
    a = partition(values, None, 0.5, 0.5, mode="random", rng=torch.Generator().manual_seed(1))
    b = partition(values, None, 0.5, 0.5, mode="random", rng=torch.Generator().manual_seed(1))
    c = partition(values, None, 0.5, 0.5, mode="random", rng=torch.Generator().manual_seed(2))
    assert a.sum() == 5 and np.array_equal(a, b) and not np.array_equal(a, c)


# ------------------------------------------------------------------ bonus standardisation
def test_standardising_a_constant_bonus_gives_zeros_not_nan():
    b = torch.full((4,), 0.7)
    z = standardize(b, b.mean(), b.var(unbiased=False), clip=3.0)
    assert torch.equal(z, torch.zeros(4))
    z = standardize(torch.tensor([0.0, 2.0]), torch.tensor(1.0), torch.tensor(1.0), clip=3.0)
    assert torch.allclose(z, torch.tensor([-1.0, 1.0]), atol=1e-6)


def test_the_standardised_bonus_is_clipped_on_both_sides():
    z = standardize(torch.tensor([-50.0, 1.0, 50.0]), torch.tensor(1.0), torch.tensor(4.0), clip=3.0)
    assert torch.allclose(z, torch.tensor([-3.0, 0.0, 3.0]), atol=1e-6)


def test_the_logit_bonus_is_clipped_at_the_configured_logit_clip():
    from rllib_asor.asor.config import AsorConfig
    from rllib_asor.asor.update import AsorState, bonus_for_rows

    cfg = AsorConfig(
        preset="paper", reward_form="logit", logit_clip=2.0, bonus_norm="off", shaping="direct",
        disc_hiddens=[1],
    )
    state = AsorState(cfg, 1)
    hidden, out = state.disc.net[0], state.disc.net[2]
    with torch.no_grad():  # logit = 10·relu(x) − 10
        hidden.weight.fill_(1.0)
        hidden.bias.zero_()
        out.weight.fill_(10.0)
        out.bias.fill_(-10.0)
    x = torch.tensor([[0.0], [1.05], [3.0]])  # logits −10, 0.5, 20
    bonus = bonus_for_rows(cfg, state, 0.5, x, x, torch.zeros(3), 0.9)
    assert torch.allclose(bonus, 0.5 * torch.tensor([-2.0, 0.5, 2.0]), atol=1e-5)


def test_one_state_is_drawn_and_empty_buckets_take_no_share():
    arch = StateArchive(feature_dim=1, capacity=50, buckets=2)
    arch.insert(torch.arange(50.0).reshape(50, 1), torch.arange(50.0), 1.0, dynamics_id=1)
    assert arch.sample(1)[0].shape == (1, 1)
    assert arch.sample(10)[0].shape == (10, 1)  # all from the one filled bucket


def test_chunks_without_termination_flags_are_archived_when_they_stop_arriving():
    from rllib_asor.asor.config import AsorConfig
    from rllib_asor.asor.update import AsorBatch, AsorState, Chunk, asor_update

    cfg = AsorConfig(mode="srpo", disc_hiddens=[4], seed=0)
    state = AsorState(cfg, 2)
    batch = AsorBatch(
        features=torch.randn(4, 2),
        env_rewards=torch.ones(4),
        values=torch.arange(4.0),
        gamma=0.9,
        chunks=[Chunk("a", 0, 2), Chunk("b", 2, 4)],
    )
    rng = np.random.default_rng(0)
    asor_update(cfg, state, None, batch, rng)
    assert len(state.archive) == 0 and state.archive.open_episodes == 2
    batch.chunks = [Chunk("c", 0, 4)]
    asor_update(cfg, state, None, batch, rng)
    assert len(state.archive) == 4 and state.archive.open_episodes == 1


def test_normalising_a_constant_feature_is_finite_and_clipped_both_ways():
    from rllib_asor.asor.networks import RunningMeanStd

    rms = RunningMeanStd(2)
    rms.update(torch.tensor([[1.0, 0.0], [1.0, 2.0]] * 500))
    z = rms.normalize(torch.tensor([[1.0, -100.0], [1.0, 100.0]]))
    assert torch.isfinite(z).all() and z[:, 0].abs().max() < 1e-3
    assert z[:, 1].tolist() == [-5.0, 5.0]


def test_the_missing_next_states_warning_is_logged_at_most_once(caplog):
    from rllib_asor.asor import update
    from rllib_asor.asor.config import AsorConfig

    cfg = AsorConfig(preset="paper", mode="srpo", shaping="potential", disc_hiddens=[4])
    state = update.AsorState(cfg, 2)
    batch = update.AsorBatch(torch.randn(4, 2), torch.ones(4), torch.arange(4.0), gamma=0.9)
    with caplog.at_level("WARNING", logger="rllib_asor.asor.update"):
        for _ in range(2):
            result = update.asor_update(cfg, state, None, batch, np.random.default_rng(0))
    # once per process: an earlier test may have logged it already
    assert sum("no next states" in r.getMessage() for r in caplog.records) <= 1
    assert result.metrics["potential"] == 0.0  # the direct form instead


def test_running_statistics_skip_an_empty_batch_and_count_a_single_row():
    from rllib_asor.asor.networks import RunningMeanStd

    rms = RunningMeanStd(2)
    rms.update(torch.zeros(0, 2))
    assert rms.mean.tolist() == [0.0, 0.0] and rms.var.tolist() == [1.0, 1.0]
    rms.update(torch.tensor([[4.0, -2.0]]))
    assert torch.allclose(rms.mean, torch.tensor([4.0, -2.0]), atol=1e-3)
    assert rms.count.item() == pytest.approx(1.0001)


def test_running_statistics_of_a_float16_batch_are_those_of_its_values_in_float64():
    from rllib_asor.asor.networks import RunningMeanStd

    x = (100.0 + torch.randn(1000, 2, generator=torch.Generator().manual_seed(0))).half()
    low, high = RunningMeanStd(2), RunningMeanStd(2)
    low.update(x)
    high.update(x.double())
    assert torch.equal(low.mean, high.mean) and torch.equal(low.var, high.var)
