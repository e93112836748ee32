"""ASOR's learner-only module on its own: its trainer's spaces and seeding, no inference, no
state for env runners, and its state round trip (an older module's state refused)."""

import gymnasium as gym
import numpy as np
import pytest
import torch

from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.proxy import ProxyInputs
from rllib_asor.rllib.modules import AsorModule

OBS = gym.spaces.Dict(
    {
        "grid": gym.spaces.Box(0, 1, (2, 4, 4), np.float32),
        "vec": gym.spaces.Box(-1, 1, (5,), np.float32),
    }
)
ACT = gym.spaces.MultiDiscrete([3, 2])


def build(**asor):
    return AsorModule(
        observation_space=OBS, action_space=ACT, model_config={"asor": AsorConfig(**asor).to_dict()}
    )


def test_a_seeded_module_is_reproducible_and_leaves_the_global_rng_alone():
    torch.manual_seed(123)
    expected_next = torch.rand(1)
    torch.manual_seed(123)
    a, b = build(seed=7), build(seed=7)
    assert torch.rand(1).item() == expected_next.item()
    for pa, pb in zip(a.parameters(), b.parameters(), strict=True):
        assert torch.equal(pa, pb)


def test_obs_keys_select_the_feature_width():
    assert build().feature_dim == 2 * 4 * 4 + 5
    assert build(obs_keys=["vec"]).feature_dim == 5
    assert build(mode="srpo").trainer.proxy is None  # value-only partition: no proxy


@pytest.mark.parametrize("proxy", ["rnd", "ensemble"])
def test_proxy_counts_are_finite_and_one_per_state(proxy):
    module = build(proxy=proxy, obs_keys=["vec"])
    x = torch.randn(16, 5)
    actions = torch.nn.functional.one_hot(torch.randint(0, 2, (16,)), 5).float()
    inputs = ProxyInputs(x, actions, x + 0.1)
    module.trainer.proxy.observe(inputs)
    counts = module.trainer.proxy.count(inputs)
    assert counts.shape == (16,) and torch.isfinite(counts).all()


def test_the_module_refuses_inference_and_sends_env_runners_nothing():
    module = build()
    with pytest.raises(NotImplementedError, match="learner-only"):
        module.forward_inference({"obs": torch.zeros(1, 37)})
    assert module.get_state(inference_only=True) == {}


def test_the_state_round_trips_and_an_older_modules_state_is_refused():
    a, b = build(seed=1, obs_keys=["vec"]), build(seed=2, obs_keys=["vec"])
    b.set_state(a.get_state())
    for pa, pb in zip(a.state_dict().values(), b.state_dict().values(), strict=True):
        assert torch.equal(pa, pb)
    old = {"state.disc.net.0.weight": np.zeros((256, 5), np.float32)}  # the old discriminator
    with pytest.raises(ValueError, match="older rllib-asor"):
        b.set_state(old)
