"""`AsorTrainer` on hand-made batches: seeding, the rows each network trains on, the losses it
steps on, what one `step` returns, and its state (optimiser moments and random streams
included) surviving a round trip while an older layout is refused in one line."""

from __future__ import annotations

import math

import pytest
import torch

from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.discriminator import discriminator_loss
from rllib_asor.asor.trainer import AsorTrainer, even_share
from tests.asor.test_state_behaviour import DIM, episodes

SMALL = {"seed": 0, "disc_hiddens": [8], "rnd_hiddens": [8], "rnd_embedding_dim": 4}


def trainer(**settings) -> AsorTrainer:
    cfg = AsorConfig(**{**SMALL, **settings})
    return AsorTrainer(cfg, DIM, 2, cfg.seed)


def params(module: torch.nn.Module) -> list[torch.Tensor]:
    return [p.detach().clone() for p in module.parameters()]


def test_a_seeded_trainer_is_reproducible_and_leaves_the_global_rng_alone():
    torch.manual_seed(123)
    expected = torch.rand(1).item()
    torch.manual_seed(123)
    a, b = trainer(), trainer()
    assert torch.rand(1).item() == expected
    for pa, pb in zip(a.parameters(), b.parameters(), strict=True):
        assert torch.equal(pa, pb)
    other = trainer(seed=1)
    assert not torch.equal(next(a.proxy.parameters()), next(other.proxy.parameters()))


@pytest.mark.parametrize(
    ("n", "minibatch", "epochs", "rows", "steps"),
    [
        (60, 16, None, None, 4),  # one pass: ⌈60/16⌉
        (60, 16, 2.0, None, 8),  # two passes: ⌈120/16⌉
        (60, 16, 0.5, None, 2),  # half a pass: ⌈30/16⌉
        (60, None, None, None, 1),  # no minibatch size: the whole batch at once
        (60, 16, None, 16.0, 1),  # a row budget: one minibatch (the fast path's default)
        (10, 16, None, None, 1),  # a minibatch larger than the batch: the batch
    ],
)
def test_the_networks_train_on_the_rows_asked_in_minibatches(n, minibatch, epochs, rows, steps):
    t = trainer(aux_epochs=epochs)
    got = list(t._minibatches(n, minibatch, rows))
    size = n if minibatch is None else min(minibatch, n)
    assert len(got) == steps and all(len(idx) == size for idx in got)
    seen = torch.cat(got)
    assert seen.max() < n and seen.min() >= 0
    if steps * size >= n:  # a full pass shows every row once before any repeats
        assert sorted(seen[:n].tolist()) == list(range(n))


def test_a_discriminator_step_minimises_the_gan_loss_plus_the_regulariser():
    t = trainer(disc_grad_penalty=1.0, disc_logit_reg=0.1, label_smoothing=0.1, disc_lr=1e-2)
    x = torch.randn(40, DIM)
    y = (torch.arange(40) % 2).float()
    disc = t.state.disc
    gan, stats = discriminator_loss(disc(x), y, 0.1)
    reg, _ = disc.regularizer(x[y > 0.5], 1.0, 0.1)
    before = float((gan + reg).detach())
    metrics = t.train_discriminator(x, y, None, None)  # one step on the whole batch
    assert metrics["disc_loss"] == pytest.approx(float(stats["disc_loss"]), abs=1e-6)
    assert metrics["js_estimate"] == pytest.approx(float(stats["js_estimate"]), abs=1e-6)
    for _ in range(20):
        t.train_discriminator(x, y, None, None)
    gan, _ = discriminator_loss(disc(x), y, 0.1)
    reg, _ = disc.regularizer(x[y > 0.5], 1.0, 0.1)
    assert float((gan + reg).detach()) < before


@pytest.mark.parametrize(("proxy", "name"), [("rnd", "rnd_loss"), ("ensemble", "ensemble_loss")])
def test_the_proxy_trains_on_the_batch_and_reports_its_loss(proxy, name):
    t = trainer(proxy=proxy, rnd_lr=1e-2)
    batch = episodes(0)
    frozen = [p.detach().clone() for p in t.proxy.parameters() if not p.requires_grad]
    first = t.train_proxy(batch.proxy_inputs, None, None)[name]
    assert math.isfinite(first)
    for _ in range(30):
        last = t.train_proxy(batch.proxy_inputs, None, None)[name]
    assert last < first
    # the RND target (frozen) never moves
    assert all(torch.equal(a, b) for a, b in
               zip(frozen, [p for p in t.proxy.parameters() if not p.requires_grad], strict=True))


def test_one_step_returns_the_bonus_from_before_training_and_both_networks_metrics():
    t = trainer(lambda_=0.1, lambda_warmup=False)
    reference = trainer(lambda_=0.1, lambda_warmup=False)
    batch = episodes(1)
    disc_before = params(t.state.disc)
    result = t.step(batch, minibatch_size=16)
    assert result.reward_delta.shape == (batch.features.shape[0],)
    assert {"disc_loss", "disc_acc_real", "rnd_loss", "lambda", "bonus_share"} <= set(result.metrics)
    assert any(not torch.equal(a, b) for a, b in zip(disc_before, params(t.state.disc), strict=True))
    # the same update without training gives the same Δr: ω was read before the step
    from rllib_asor.asor.update import asor_update

    expected = asor_update(reference.cfg, reference.state, reference.proxy, batch, reference.rng)
    torch.testing.assert_close(result.reward_delta, expected.reward_delta)


def test_the_state_round_trips_with_the_optimisers_moments_and_random_streams():
    a = trainer()
    for seed in range(3):
        a.step(episodes(seed), minibatch_size=16)
    b = trainer(seed=5)
    b.set_state(a.get_state())
    for pa, pb in zip(a.state_dict().values(), b.state_dict().values(), strict=True):
        assert torch.equal(pa, pb)
    assert a.disc_optimizer.state_dict()["state"][0]["step"] == b.disc_optimizer.state_dict()["state"][0]["step"]
    # the next step is the same on both: the same draws, the same moments
    ra, rb = a.step(episodes(7), minibatch_size=16), b.step(episodes(7), minibatch_size=16)
    torch.testing.assert_close(ra.reward_delta, rb.reward_delta)
    for pa, pb in zip(a.parameters(), b.parameters(), strict=True):
        torch.testing.assert_close(pa, pb)


def test_a_state_of_the_older_layout_is_refused_in_one_line():
    t = trainer()
    old = {"state.disc.net.0.weight": torch.zeros(8, DIM)}  # the discriminator module's keys
    with pytest.raises(ValueError, match="older rllib-asor") as err:
        t.set_state(old)
    assert "\n" not in str(err.value) and "allowed" in str(err.value)


def test_even_shares_are_equal_blocks_in_rank_order():
    rows = torch.arange(10)
    assert [even_share(rows, r, 3).tolist() for r in range(3)] == [[0, 1, 2], [3, 4, 5], [6, 7, 8]]
    assert even_share(None, 0, 2) is None


def test_the_networks_train_when_called_under_no_grad():
    """RLlib runs Learner connectors under no_grad on some Learners: training still steps."""
    t = trainer()
    before = params(t.state.disc)
    with torch.no_grad():
        t.step(episodes(0), minibatch_size=16)
    assert any(not torch.equal(a, b) for a, b in zip(before, params(t.state.disc), strict=True))


@pytest.mark.parametrize("penalty", [0.0, 2.0])
def test_the_one_pass_training_loss_is_the_gan_loss_plus_the_regulariser_and_its_gradient(penalty):
    """`Discriminator.training_loss` takes the gradient penalty on its own pass's real rows:
    the same loss and parameter gradients as a second pass over them."""
    disc = trainer(disc_input_norm=True).state.disc
    disc.observe(torch.randn(50, DIM) * 3 + 1)
    x, y = torch.randn(12, DIM), (torch.arange(12) % 3 == 0).float()
    one, stats = disc.training_loss(x, y, 0.1, penalty, 0.05)
    gan, _ = discriminator_loss(disc(x), y, 0.1)
    reg, reg_stats = disc.regularizer(x[y > 0.5], penalty, 0.05)
    torch.testing.assert_close(one, gan + reg)
    assert stats["disc_grad_penalty"] == pytest.approx(float(reg_stats["disc_grad_penalty"]))
    g_one = torch.autograd.grad(one, list(disc.parameters()))
    g_two = torch.autograd.grad(gan + reg, list(disc.parameters()))
    for a, b in zip(g_one, g_two, strict=True):
        torch.testing.assert_close(a, b)
    if penalty:
        assert stats["disc_grad_penalty"] > 0


def _adam_steps(optimizer: torch.optim.Optimizer) -> set[int]:
    return {int(s["step"]) for s in optimizer.state.values()}


@pytest.mark.parametrize(("minibatch", "rows"), [(16, None), (8, 16.0), (None, None)])
def test_both_networks_take_the_steps_asked_of_them(minibatch, rows):
    t = trainer()
    batch = episodes(1)
    result = t.step(batch, minibatch_size=minibatch, rows=rows)

    def steps(n: int) -> int:
        budget = n if rows is None else rows
        return 1 if minibatch is None else math.ceil(budget / min(minibatch, n))

    assert _adam_steps(t.disc_optimizer) == {steps(result.disc_features.shape[0])}
    assert _adam_steps(t.proxy_optimizer) == {steps(batch.features.shape[0])}


def test_the_learning_rates_reach_the_networks():
    slow, default = trainer(disc_lr=1e-9, rnd_lr=1e-9), trainer()
    before = params(slow.state.disc), params(slow.proxy)
    batch = episodes(1)
    for t in (slow, default):
        t.step(batch, minibatch_size=16)
    for net, start, moved in ((slow.state.disc, before[0], default.state.disc),
                              (slow.proxy, before[1], default.proxy)):  # fmt: skip
        change = max((a - b).abs().max().item() for a, b in zip(params(net), start, strict=True))
        default_change = max(
            (a - b).abs().max().item() for a, b in zip(params(moved), start, strict=True)
        )
        assert change < 1e-6 < default_change
