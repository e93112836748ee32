"""PaddedMultiCategorical is RLlib's TorchMultiCategorical, computed on one padded tensor."""

import numpy as np
import pytest
import torch
from ray.rllib.core.distribution.torch.torch_distribution import TorchMultiCategorical

from rllib_asor.race.action_dist import PaddedMultiCategorical

NVEC = [3, 3, 2, 2, 2, 2, 8, 2]  # the race's action heads


def both(logits):
    return (
        PaddedMultiCategorical.from_logits(logits, input_lens=NVEC),
        TorchMultiCategorical.from_logits(logits, input_lens=NVEC),
    )


@pytest.mark.parametrize("lead", [(5,), (4, 3)])  # [B] and recurrent [B, T]
def test_logp_entropy_kl_and_their_gradients_match_rllibs(lead):
    torch.manual_seed(0)
    logits = (3 * torch.randn(*lead, sum(NVEC))).requires_grad_()
    other = 3 * torch.randn(*lead, sum(NVEC))
    actions = torch.stack([torch.randint(n, lead) for n in NVEC], dim=-1)
    ours, theirs = both(logits)
    ours_other, theirs_other = both(other)
    for name, a, b in [
        ("logp", ours.logp(actions), theirs.logp(actions)),
        ("entropy", ours.entropy(), theirs.entropy()),
        ("kl", ours.kl(ours_other), theirs.kl(theirs_other)),
    ]:
        assert a.shape == lead, name
        torch.testing.assert_close(a, b, msg=name)
        (grad_a,) = torch.autograd.grad(a.sum(), logits, retain_graph=True)
        (grad_b,) = torch.autograd.grad(b.sum(), logits, retain_graph=True)
        assert torch.isfinite(grad_a).all(), name
        torch.testing.assert_close(grad_a, grad_b, msg=name)


def test_samples_follow_each_heads_probabilities():
    torch.manual_seed(1)
    logits = torch.randn(1, sum(NVEC)).expand(20000, -1)
    ours, theirs = both(logits)
    samples = ours.sample()
    assert samples.shape == (20000, len(NVEC)) and samples.dtype == torch.int64
    for head, cat in enumerate(theirs._cats):
        freq = np.bincount(samples[:, head].numpy(), minlength=NVEC[head]) / len(samples)
        assert freq.shape == (NVEC[head],)  # never a padded category
        np.testing.assert_allclose(freq, cat._dist.probs[0].numpy(), atol=0.015)


def test_deterministic_and_per_head_views_match_rllibs():
    torch.manual_seed(2)
    logits = torch.randn(6, sum(NVEC))
    ours, theirs = both(logits)
    assert torch.equal(ours.to_deterministic().sample(), theirs.to_deterministic().sample())
    assert len(ours._cats) == len(NVEC)  # RLlib code that walks the heads still can
    torch.testing.assert_close(ours.kl(theirs), theirs.kl(theirs))


def test_wrong_logit_size_is_a_clear_error():
    with pytest.raises(ValueError, match="must sum to the logits' size 5"):
        PaddedMultiCategorical.from_logits(torch.zeros(2, 5), input_lens=NVEC)
