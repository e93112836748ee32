"""ASOR's pieces make their tensors on the device, and in the dtype, of the data they meet.

CI has no GPU. Here the data is on the CPU and torch's *default* device is "meta" (a device
without storage) while the code runs: a factory call that ignores the data's device makes a
meta tensor, which then fails `.item()` or turns up in the result, as a CPU tensor would on a
GPU Learner. The same calls with the default left alone give the reference values.
tests/test_state_devices.py does this for whole updates; here are the edge cases an update
rarely reaches: an empty archive or discriminator batch, a single target, numpy input, a
torch generator for the random partition.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import gymnasium as gym
import numpy as np
import pytest
import torch

from rllib_asor.asor.archive import StateArchive
from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.discriminator import Discriminator, discriminator_loss
from rllib_asor.asor.networks import flatten
from rllib_asor.asor.partition import partition
from rllib_asor.asor.proxy import make_proxy
from rllib_asor.asor.reward import explained_variance
from rllib_asor.asor.update import AsorState, asor_update
from tests.asor.test_state_behaviour import DIM, episodes


@contextmanager
def default_dtype(dtype: torch.dtype) -> Iterator[None]:
    old = torch.get_default_dtype()
    torch.set_default_dtype(dtype)
    try:
        yield
    finally:
        torch.set_default_dtype(old)


def _on_cpu(*tensors: torch.Tensor) -> bool:
    return all(t.device.type == "cpu" for t in tensors)


def test_the_archive_samples_on_its_own_device_under_another_default() -> None:
    arch = StateArchive(feature_dim=2, capacity=8, buckets=2)
    with torch.device("meta"):
        empty = arch.sample(4)
    arch.insert(torch.arange(8.0).reshape(4, 2), torch.arange(4.0), 1.0, dynamics_id=1)
    expected = arch.sample(3, torch.Generator().manual_seed(0))
    with torch.device("meta"):
        nothing = arch.sample(0)
        seeded = arch.sample(3, torch.Generator().manual_seed(0))
        unseeded = arch.sample(3)
    assert _on_cpu(*empty, *nothing, *seeded, *unseeded)
    assert empty[0].shape == nothing[0].shape == (0, 2) and len(empty[1]) == len(nothing[1]) == 0
    assert torch.equal(seeded[0], expected[0]) and torch.equal(seeded[1], expected[1])
    assert unseeded[0].shape == (3, 2)


def test_discriminator_loss_and_regulariser_stay_on_the_logits_device() -> None:
    logits, labels = torch.tensor([2.0, -1.0, 0.5]), torch.tensor([1.0, 0.0, 0.0])
    fake, none = torch.zeros(3), torch.zeros(0)
    disc = Discriminator(2, [4])
    real = torch.randn(3, 2, generator=torch.Generator().manual_seed(0))
    cases = {
        "mixed": lambda: discriminator_loss(logits, labels, 0.1),
        "one-sided": lambda: discriminator_loss(logits, fake),
        "empty": lambda: discriminator_loss(none, none),
        "no regulariser": lambda: disc.regularizer(real, 0.0, 0.0),
        "penalty only": lambda: disc.regularizer(real, 1.0, 0.0),
    }
    for name, run in cases.items():
        loss, stats = run()
        with torch.device("meta"):
            got_loss, got_stats = run()
        assert _on_cpu(got_loss, *got_stats.values()), name
        assert got_loss.item() == loss.item(), name
        for key, value in stats.items():
            assert torch.equal(got_stats[key], value), (name, key)


def test_discriminator_statistics_keep_the_logits_dtype_under_another_default_dtype() -> None:
    logits = torch.tensor([2.0, -1.0, 0.5])
    for labels in (torch.tensor([1.0, 0.0, 0.0]), torch.zeros(3), torch.ones(3)):
        with default_dtype(torch.float64):
            loss, stats = discriminator_loss(logits, labels)
        assert loss.dtype == torch.float32
        assert {k: v.dtype for k, v in stats.items()} == dict.fromkeys(stats, torch.float32)


def test_flatten_makes_host_data_on_the_cpu_under_another_default() -> None:
    box, discrete = gym.spaces.Box(-1, 1, (2,)), gym.spaces.Discrete(3)
    with torch.device("meta"):
        b = flatten(np.array([[0.5, -0.5]], np.float32), box)
        d = flatten([2, 0], discrete)
    assert _on_cpu(b, d)
    assert b.tolist() == [[0.5, -0.5]] and d.tolist() == [[0, 0, 1], [1, 0, 0]]


def test_the_random_partition_draws_from_a_torch_generator_under_another_default() -> None:
    values = np.arange(20.0)
    expected = partition(values, None, 0.5, 0.5, mode="random", rng=torch.Generator().manual_seed(1))
    with torch.device("meta"):
        got = partition(values, None, 0.5, 0.5, mode="random", rng=torch.Generator().manual_seed(1))
    assert np.array_equal(got, expected) and got.sum() == 5


def test_explained_variance_of_one_target_under_another_default() -> None:
    v1, t1, v2, t2 = torch.tensor([1.0]), torch.tensor([2.0]), torch.tensor([1.0, 2.5]), torch.tensor([1.0, 2.0])
    with torch.device("meta"):
        one, two = explained_variance(v1, t1), explained_variance(v2, t2)
    assert one == -1.0 and two == pytest.approx(0.75)  # 1 − Var([0, −0.5]) / Var([1, 2])


def test_the_critic_ev_of_an_update_under_another_default() -> None:
    cfg = AsorConfig(seed=0, preset="paper", mode="srpo", disc_hiddens=[8])
    batch = episodes(0)

    def update(state: AsorState) -> tuple[float, torch.Tensor]:
        result = asor_update(cfg, state, None, batch, np.random.default_rng(0))
        return result.metrics["critic_ev"], result.reward_delta

    torch.manual_seed(0)
    ev, delta = update(AsorState(cfg, DIM))
    torch.manual_seed(0)
    state = AsorState(cfg, DIM)
    with torch.device("meta"):
        got_ev, got_delta = update(state)
    assert got_ev == ev == pytest.approx(1.0)  # V is the chunks' discounted return
    assert _on_cpu(got_delta) and torch.equal(got_delta, delta)


def test_the_archive_update_under_another_default_device_and_dtype() -> None:
    """The robust default (archive): a first batch whose episodes are still open (nothing to
    draw), then one that ends them (the archive is filled, and drawn from)."""
    cfg = AsorConfig(seed=0, disc_hiddens=[8], rnd_hiddens=[8], rnd_embedding_dim=4)
    batches = [episodes(0, terminated=False), episodes(1)]

    def run(state: AsorState, proxy: torch.nn.Module) -> list:
        rng = np.random.default_rng(0)
        return [asor_update(cfg, state, proxy, b, rng) for b in batches]

    def build() -> tuple[AsorState, torch.nn.Module]:
        torch.manual_seed(0)
        proxy = make_proxy(cfg, DIM, 2, seed=1)
        assert proxy is not None
        return AsorState(cfg, DIM), proxy

    expected = run(*build())
    parts = build()
    with torch.device("meta"):
        on_meta = run(*parts)
    parts = build()
    with default_dtype(torch.float64):
        in_float64 = run(*parts)
    assert int(expected[0].disc_labels.sum()) == 0 and int(expected[1].disc_labels.sum()) > 0
    for got in (on_meta, in_float64):
        for a, b in zip(expected, got, strict=True):
            for name in ("reward_delta", "disc_features", "disc_labels"):
                x, y = getattr(a, name), getattr(b, name)
                assert _on_cpu(y) and y.dtype == torch.float32 and torch.equal(x, y), name
