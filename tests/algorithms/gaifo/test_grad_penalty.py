"""GAIfO's gradient penalty forms on hand-made discriminators whose input gradient is known
(`zero_centred`, the default, and `one_centred_mix`, the GARAT authors' `compute_grad_pen`),
the trainer's use of them, GARAT's forwarding and the setting's validation."""

from __future__ import annotations

import pytest
import torch

from rllib_asor.algorithms.gaifo.discriminator import TransitionDiscriminator
from rllib_asor.algorithms.gaifo.settings import GaifoSettings
from rllib_asor.algorithms.gaifo.trainer import GaifoTrainer
from rllib_asor.algorithms.garat.settings import GaratSettings
from tests.algorithms.gaifo.test_gaifo import _demos

DEVICE = torch.device("cpu")


def _kinked(w: list[float], b: float, v: float) -> TransitionDiscriminator:
    """D with one hidden ReLU unit: logit = v · relu(w · z + b) (z the normalised input, here the
    input itself: mean 0, std 1), so ∇_z logit = v · w where w · z + b > 0, else 0."""
    disc = TransitionDiscriminator(len(w), hiddens=(1,)).to(DEVICE)
    with torch.no_grad():
        disc.net[0].weight.copy_(torch.tensor([w], device=DEVICE))
        disc.net[0].bias.fill_(b)
        disc.net[2].weight.fill_(v)
        disc.net[2].bias.fill_(0.0)
    return disc


def test_zero_centred_is_the_squared_gradient_norm_at_real_rows():
    disc = _kinked([3.0, 4.0], b=100.0, v=1.0)  # ‖∇ logit‖ = ‖(3, 4)‖ = 5 everywhere here
    real = torch.tensor([[0.5, -1.0], [1.0, 2.0]], device=DEVICE)
    assert disc.gradient_penalty(real).item() == pytest.approx(25.0)
    assert disc.gradient_penalty(real, form="zero_centred").item() == pytest.approx(25.0)


def test_one_centred_mix_is_the_squared_distance_of_the_norm_from_one():
    real = torch.tensor([[0.5, -1.0], [1.0, 2.0]], device=DEVICE)
    fake = torch.tensor([[-1.0, 0.0], [0.0, 1.0]], device=DEVICE)
    linear = _kinked([3.0, 4.0], b=100.0, v=1.0)  # norm 5 at every mixture: (5 − 1)² = 16
    assert linear.gradient_penalty(real, fake, "one_centred_mix").item() == pytest.approx(16.0)
    unit = _kinked([0.6, 0.8], b=100.0, v=1.0)  # norm 1: no penalty
    assert unit.gradient_penalty(real, fake, "one_centred_mix").item() == pytest.approx(0.0)


def test_one_centred_mix_reads_mixtures_with_normal_weights_per_element():
    # norm 3 where z₀ > 0, else 0: penalty 4 there, 1 elsewhere. Real z₀ = 1, fake z₀ = −1: the
    # mixture's z₀ = 2α − 1 > 0 iff α > ½, P = 0.3085 for α ~ N(0, 1) (0.5 for α ~ U(0, 1)).
    disc = _kinked([1.0, 0.0], b=0.0, v=3.0)
    n = 40_000
    real = torch.tensor([[1.0, 0.0]], device=DEVICE).repeat(n, 1)
    fake = torch.tensor([[-1.0, 0.0]], device=DEVICE).repeat(n, 1)
    torch.manual_seed(0)
    gp = disc.gradient_penalty(real, fake, "one_centred_mix").item()
    assert gp == pytest.approx(0.3085 * 4 + 0.6915 * 1, abs=0.03)
    assert disc.gradient_penalty(real, form="zero_centred").item() == pytest.approx(9.0)


def test_one_centred_mix_pairs_the_first_rows_of_each_and_is_zero_without_fake_rows():
    disc = _kinked([3.0, 4.0], b=100.0, v=1.0)  # norm 5 everywhere: (5 − 1)² = 16
    real = torch.ones(3, 2, device=DEVICE)
    assert disc.gradient_penalty(real, None, "one_centred_mix").item() == 0.0
    assert disc.gradient_penalty(real, real[:0], "one_centred_mix").item() == 0.0
    assert disc.gradient_penalty(real, real[:1], "one_centred_mix").item() == pytest.approx(16.0)
    # z₀ > 0 only on the first real row (norm 3: penalty 4), the mixture with its pair
    # (z₀ = α·1 + (1 − α)·1 = 1 > 0 whatever α) keeps it there; the third row is never read.
    kinked = _kinked([1.0, 0.0], b=0.0, v=3.0)
    real = torch.tensor([[1.0, 0.0], [1.0, 0.0], [-1.0, 0.0]], device=DEVICE)
    fake = torch.tensor([[1.0, 0.0], [1.0, 0.0]], device=DEVICE)
    assert kinked.gradient_penalty(real, fake, "one_centred_mix").item() == pytest.approx(4.0)


def test_trainer_adds_the_chosen_form_and_reports_it():
    for form in ("zero_centred", "one_centred_mix"):
        settings = GaifoSettings(grad_penalty=10.0, grad_penalty_form=form, disc_steps=3,
                                 disc_hiddens=(8,), input_norm=False)
        trainer = GaifoTrainer(settings, _demos(), DEVICE)
        policy = trainer.features(torch.zeros(8, 2, device=DEVICE), torch.ones(8, 2, device=DEVICE))
        stats = trainer.update(policy)
        assert stats["disc_grad_penalty"].item() >= 0.0
    assert GaifoSettings().grad_penalty_form == "zero_centred"  # GAIfO's default, as before


def test_garat_has_the_setting_with_the_same_default():
    assert GaratSettings().grad_penalty_form == "zero_centred"
    assert GaratSettings(grad_penalty_form="one_centred_mix").grad_penalty_form == (
        "one_centred_mix"
    )


def test_a_bad_form_is_one_line_naming_the_allowed_values():
    allowed = r"expected zero_centred \| one_centred_mix"
    with pytest.raises(ValueError, match=f"gaifo.grad_penalty_form='wgan' is not allowed; {allowed}"):
        GaifoSettings(grad_penalty_form="wgan")
    with pytest.raises(ValueError, match=f"garat.grad_penalty_form='wgan' is not allowed; {allowed}"):
        GaratSettings(grad_penalty_form="wgan")
    disc = _kinked([3.0, 4.0], b=100.0, v=1.0)
    with pytest.raises(ValueError, match=r"grad_penalty_form='wgan'; allowed: zero_centred \| "):
        disc.gradient_penalty(torch.ones(1, 2, device=DEVICE), form="wgan")
