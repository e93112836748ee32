"""The auxiliary modules on their own: seeding, spaces, learner-only behaviour."""

import gymnasium as gym
import numpy as np
import pytest
import torch

from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.proxy import ProxyInputs
from rllib_asor.rllib.modules import AsorDiscriminatorModule, AsorProxyModule

OBS = gym.spaces.Dict(
    {
        "grid": gym.spaces.Box(0, 1, (2, 4, 4), np.float32),
        "vec": gym.spaces.Box(-1, 1, (5,), np.float32),
    }
)
ACT = gym.spaces.MultiDiscrete([3, 2])


def build(cls, **asor):
    return cls(
        observation_space=OBS, action_space=ACT, model_config={"asor": AsorConfig(**asor).to_dict()}
    )


def test_seeded_modules_are_reproducible_and_leave_the_global_rng_alone():
    torch.manual_seed(123)
    expected_next = torch.rand(1)
    torch.manual_seed(123)
    a = build(AsorDiscriminatorModule, seed=7)
    b = build(AsorDiscriminatorModule, seed=7)
    assert torch.rand(1).item() == expected_next.item()
    for pa, pb in zip(a.parameters(), b.parameters(), strict=True):
        assert torch.equal(pa, pb)


def test_obs_keys_select_the_feature_width():
    assert build(AsorDiscriminatorModule).feature_dim == 2 * 4 * 4 + 5
    assert build(AsorProxyModule, obs_keys=["vec"]).feature_dim == 5


@pytest.mark.parametrize("proxy", ["rnd", "ensemble"])
def test_proxy_counts_are_finite_and_one_per_state(proxy):
    module = build(AsorProxyModule, proxy=proxy, obs_keys=["vec"])
    x = torch.randn(16, 5)
    actions = torch.nn.functional.one_hot(torch.randint(0, 2, (16,)), 5).float()
    inputs = ProxyInputs(x, actions, x + 0.1)
    module.proxy.observe(inputs)
    counts = module.proxy.count(inputs)
    assert counts.shape == (16,) and torch.isfinite(counts).all()


def test_learner_only_modules_refuse_inference():
    with pytest.raises(NotImplementedError, match="learner-only"):
        build(AsorDiscriminatorModule).forward_inference({"obs": torch.zeros(1, 37)})


class _Metrics:
    def __init__(self):
        self.logged = {}

    def log_value(self, key, value, window=None):
        self.logged[key] = (value, window)

    def log_dict(self, stats, key=None, window=None):
        self.logged.update({(key, k): (v, window) for k, v in stats.items()})


class _Learner:
    def __init__(self):
        self.metrics = _Metrics()


@pytest.mark.parametrize(("proxy", "name"), [("rnd", "rnd_loss"), ("ensemble", "ensemble_loss")])
def test_proxy_loss_is_returned_and_logged_under_its_name(proxy, name):
    from ray.rllib.core.columns import Columns

    from rllib_asor.rllib.modules import proxy_batch

    module = build(AsorProxyModule, proxy=proxy, obs_keys=["vec"], seed=0)
    x = ProxyInputs(torch.randn(8, 5), torch.randn(8, 5), torch.randn(8, 5))
    batch = proxy_batch(x)
    fwd = module.forward_train(batch)
    learner = _Learner()
    loss = module.compute_self_supervised_loss(
        learner=learner, module_id="m", config=None, batch=batch, fwd_out=fwd
    )
    assert torch.equal(loss, fwd["proxy_loss"]) and loss.requires_grad
    assert torch.allclose(loss, module.proxy.loss(x))
    assert learner.metrics.logged == {("m", name): (pytest.approx(loss.item()), 1)}
    assert set(batch) >= {Columns.OBS, Columns.NEXT_OBS}


def test_discriminator_and_proxy_of_one_seed_start_from_different_weights():
    disc = build(AsorDiscriminatorModule, seed=3, disc_hiddens=[8], rnd_hiddens=[8])
    proxy = build(AsorProxyModule, seed=3, disc_hiddens=[8], rnd_hiddens=[8])
    again = build(AsorProxyModule, seed=3, disc_hiddens=[8], rnd_hiddens=[8])
    other = build(AsorProxyModule, seed=4, disc_hiddens=[8], rnd_hiddens=[8])
    first = lambda m: next(m.parameters()).detach()  # noqa: E731
    assert torch.equal(first(proxy), first(again)) and not torch.equal(first(proxy), first(other))
    assert first(disc).shape != first(proxy).shape or not torch.equal(first(disc), first(proxy))


def test_proxy_module_is_seeded_and_leaves_the_global_rng_alone():
    torch.manual_seed(5)
    expected_next = torch.rand(1)
    torch.manual_seed(5)
    a = build(AsorProxyModule, seed=7, obs_keys=["vec"])
    b = build(AsorProxyModule, seed=7, obs_keys=["vec"])
    assert torch.rand(1).item() == expected_next.item()
    for pa, pb in zip(a.parameters(), b.parameters(), strict=True):
        assert torch.equal(pa, pb)


@pytest.mark.parametrize("smoothing", [0.0, 0.2])
def test_discriminator_loss_uses_the_label_smoothing_and_regularises_real_rows(smoothing):
    from ray.rllib.core.columns import Columns

    from rllib_asor.asor.discriminator import discriminator_loss
    from rllib_asor.rllib.modules import LABEL

    module = build(
        AsorDiscriminatorModule,
        seed=0,
        obs_keys=["vec"],
        label_smoothing=smoothing,
        disc_grad_penalty=1.0,
        disc_logit_reg=0.1,
    )
    obs = torch.randn(10, 5)
    labels = (torch.arange(10) % 2).float()
    batch = {Columns.OBS: obs, LABEL: labels}
    learner = _Learner()
    loss = module.compute_self_supervised_loss(
        learner=learner,
        module_id="d",
        config=None,
        batch=batch,
        fwd_out=module.forward_train(batch),
    )
    gan, _ = discriminator_loss(module.logits(obs), labels, smoothing)
    reg, _ = module.disc.regularizer(obs[labels > 0.5], 1.0, 0.1)
    torch.testing.assert_close(loss, gan + reg)
    assert learner.metrics.logged[("d", "disc_loss")][1] == 1
