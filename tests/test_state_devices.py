"""Device-correctness on a CPU-only machine: the wrong default device, and state that moves.

On a GPU Learner a tensor made without a device lands on the CPU while the data it meets is on
cuda. Here the data and the modules are on the CPU and torch's *default* device is set to
"meta" (a device without storage) while the code runs: a factory call that does not take the
device of the data it meets makes a meta tensor, and the first `torch.cat`, arithmetic or
`.item()` with real tensors fails, exactly as on a GPU. The same updates pass with the default
left alone, so a failure here names a missing device, not a broken test.

ASOR's state (discriminator, normalisers, archive, λ, the proxy) must move with `.to(device)`:
after `.to("meta")` no tensor may be left behind on the CPU, and a state saved from one module
restores (`torch.load(map_location=...)`, `load_state_dict`) into one rebuilt on another device.
"""

from __future__ import annotations

import io
from collections.abc import Iterator

import numpy as np
import pytest
import torch
from torch import nn

from rllib_asor.algorithms.maple.ensemble import GaussianEnsemble
from rllib_asor.algorithms.maple.rollout import ClipRange, model_rollout
from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.discriminator import discriminator_loss
from rllib_asor.asor.proxy import make_proxy
from rllib_asor.asor.update import AsorBatch, AsorState, asor_update
from tests.asor.test_state_behaviour import DIM, episodes

CASES = {
    "robust default (archive, potential shaping)": {},
    "paper": {"preset": "paper"},
    "auto lambda": {"lambda_": "auto", "lambda_warmup": True},
    "ensemble proxy": {"proxy": "ensemble"},
    "per-dynamics rnd, input norm": {"proxy": "rnd_per_dynamics", "disc_input_norm": True},
    "random mode, batch norm, gail": {"mode": "random", "bonus_norm": "batch", "reward_form": "gail"},
    "srpo, centered, direct": {"mode": "srpo", "reward_form": "centered", "shaping": "direct"},
}


def _build(cfg: AsorConfig) -> tuple[AsorState, nn.Module | None]:
    torch.manual_seed(0)
    state = AsorState(cfg, DIM)
    proxy = make_proxy(cfg, DIM, 2, seed=1) if cfg.needs_proxy else None
    return state, proxy


def _batches(calls: int) -> list[AsorBatch]:
    """Hand-made batches on the CPU; some episodes end by truncation."""
    return [episodes(i, terminated=i % 2 == 0) for i in range(calls)]


def _run(cfg: AsorConfig, state: AsorState, proxy: nn.Module | None, batches: list) -> list:
    """One update per batch (the archive fills, episodes close) and the discriminator's and
    proxy's losses, as the Learner computes them."""
    rng, out = np.random.default_rng(0), []
    for batch in batches:
        result = asor_update(cfg, state, proxy, batch, rng)
        loss, _ = discriminator_loss(state.disc(result.disc_features), result.disc_labels, 0.1)
        real = result.disc_features[result.disc_labels > 0.5]
        reg, _ = state.disc.regularizer(real, cfg.disc_grad_penalty, 0.01)
        if proxy is not None:
            loss = loss + proxy.loss(batch.proxy_inputs)
        out.append((result, (loss + reg).item()))
    return out


def _cfg(case: str) -> AsorConfig:
    return AsorConfig(seed=0, disc_hiddens=[16], rnd_hiddens=[16], rnd_embedding_dim=8, **CASES[case])


@pytest.mark.parametrize("case", sorted(CASES))
def test_asor_update_makes_every_tensor_on_the_device_of_its_data(case: str) -> None:
    cfg = _cfg(case)
    expected = _run(cfg, *_build(cfg), _batches(3))
    state, proxy, batches = *_build(cfg), _batches(3)
    with torch.device("meta"):  # a tensor made without the data's device lands here
        got = _run(cfg, state, proxy, batches)
    for (a, loss_a), (b, loss_b) in zip(expected, got, strict=True):
        for t in (b.reward_delta, b.disc_features, b.disc_labels):
            assert t.device.type == "cpu"
        assert torch.equal(a.reward_delta, b.reward_delta)
        assert torch.equal(a.disc_labels, b.disc_labels)
        assert loss_a == loss_b and np.isfinite(loss_b)


def test_the_meta_default_catches_a_tensor_made_off_the_data_device() -> None:
    """The mechanism itself: a device-less factory call fails where the code mixes it in."""
    data = torch.zeros(3)
    with torch.device("meta"), pytest.raises(RuntimeError):
        torch.cat([data, torch.full((2,), 1.0)])
    with torch.device("meta"):
        assert torch.cat([data, torch.full((2,), 1.0, device=data.device)]).device == data.device


def _tensors_left_behind(module: nn.Module, device: str) -> Iterator[str]:
    """Tensors that sit in a module's attributes (not parameters or buffers) off `device`:
    state that `.to()` would not move."""
    for name, sub in module.named_modules():
        for attr, value in vars(sub).items():
            if isinstance(value, torch.Tensor) and value.device.type != device:
                yield f"{name}.{attr}" if name else attr


@pytest.mark.parametrize("case", sorted(CASES))
def test_asor_state_moves_with_its_module_and_restores_across_devices(case: str) -> None:
    cfg = _cfg(case)
    state, proxy = _build(cfg)
    _run(cfg, state, proxy, _batches(2))
    if state.archive is not None:
        state.archive.end_call(0.9)  # close the open episodes: they are not checkpointed
        assert len(state.archive) > 0
    modules = {"state": state} | ({"proxy": proxy} if proxy is not None else {})
    saved = {}
    for key, module in modules.items():
        buf = io.BytesIO()
        torch.save(module.state_dict(), buf)
        saved[key] = buf.getvalue()

    # Every tensor of ASOR's state moves with .to(): nothing is left behind on the CPU.
    moved = {key: _rebuilt(cfg, key).to("meta") for key in modules}
    for key, module in moved.items():
        assert all(t.device.type == "meta" for t in module.state_dict().values()), key
        assert not list(_tensors_left_behind(module, "meta")), key
    # The state restores into the modules on their new device (saved on one device, loaded on
    # another through map_location), and back onto the CPU.
    for key, module in moved.items():
        module.load_state_dict(torch.load(io.BytesIO(saved[key]), map_location="meta"))
        module.to_empty(device="cpu")
        module.load_state_dict(torch.load(io.BytesIO(saved[key]), map_location="cpu"))
        original = modules[key].state_dict()
        for name, value in module.state_dict().items():
            assert value.device.type == "cpu" and torch.equal(value, original[name]), name

    # The restored state gives the same next update as the original.
    state2, proxy2 = moved["state"], moved.get("proxy")
    a = asor_update(cfg, state, proxy, episodes(10), np.random.default_rng(5))
    b = asor_update(cfg, state2, proxy2, episodes(10), np.random.default_rng(5))
    assert torch.equal(a.reward_delta, b.reward_delta)
    assert torch.equal(a.disc_labels, b.disc_labels)


def _rebuilt(cfg: AsorConfig, key: str) -> nn.Module:
    torch.manual_seed(99)  # other initial weights: only the restore can make them equal
    if key == "state":
        return AsorState(cfg, DIM)
    proxy = make_proxy(cfg, DIM, 2, seed=7)
    assert proxy is not None
    return proxy


def test_maple_model_rollout_makes_its_tensors_on_the_ensemble_device() -> None:
    torch.manual_seed(0)
    model = GaussianEnsemble(3, 1, members=3, elites=2, hidden=8)
    starts = {
        "obs": np.random.default_rng(0).normal(size=(16, 3)).astype(np.float32),
        "last_actions": np.zeros((16, 1), np.float32),
        "policy_hidden": np.zeros((16, 2), np.float32),
        "value_hidden": np.zeros((16, 2), np.float32),
    }
    limits = ClipRange(np.full(3, -5, np.float32), np.full(3, 5, np.float32), -10.0, 10.0)

    def policy(obs: torch.Tensor, last: torch.Tensor, hidden: torch.Tensor):
        return torch.tanh(obs[:, :1]), hidden + 1.0

    def never(nxt: np.ndarray) -> np.ndarray:
        return np.zeros(len(nxt), bool)

    def roll() -> dict[str, np.ndarray]:
        seg, _ = model_rollout(
            model, policy, starts, 4, never, limits, 0.25, 40.0, np.random.default_rng(1)
        )
        return seg

    expected = roll()
    with torch.device("meta"):
        got = roll()
    for key, value in expected.items():
        np.testing.assert_array_equal(got[key], value, err_msg=key)


def test_maple_asor_bonus_makes_its_tensors_on_the_device_of_its_data() -> None:
    from tests.rllib.test_soft_q_glue import _maple_case, maple_asor_bonus

    cfg = _cfg("robust default (archive, potential shaping)")
    case = _maple_case()

    def bonus(state: AsorState, proxy: nn.Module | None) -> torch.Tensor:
        delta, _ = maple_asor_bonus(cfg, state, proxy, *case, np.random.default_rng(0))
        return delta

    expected = bonus(*_build(cfg))
    state, proxy = _build(cfg)
    with torch.device("meta"):
        got = bonus(state, proxy)
    assert got.device.type == "cpu" and torch.equal(got, expected)


@pytest.mark.parametrize("algorithm", ["ppo", "sac"])
def test_the_asor_connector_makes_its_tensors_on_the_device_of_the_batch(
    ray_session, monkeypatch, algorithm: str
) -> None:
    """The ASOR piece of a real PPO and SAC Learner (the critic's values, the features, the
    reward rewrite, the aux batches) under the wrong default device; RLlib's own code runs as
    usual (it is not ours to check)."""
    from rllib_asor.rllib.connector import AsorRewardConnector
    from tests.test_gpu_training import lava, sac

    piece = AsorRewardConnector.__call__

    def on_the_wrong_default(self: AsorRewardConnector, **kwargs: object) -> object:
        with torch.device("meta"):
            return piece(self, **kwargs)

    monkeypatch.setattr(AsorRewardConnector, "__call__", on_the_wrong_default)
    # SAC: the first iteration samples the 64 warm-up steps and ends with one update
    config, iterations = (lava(True), 1) if algorithm == "ppo" else (sac(True), 1)
    algo = config.build_algo()
    try:
        for _ in range(iterations):
            result = algo.train()
    finally:
        algo.stop()
    assert np.isfinite(result["asor"]["disc_loss"]) and np.isfinite(result["asor"]["lambda"])


def test_evaluation_helpers_make_their_inputs_on_the_module_device() -> None:
    """The race's batched policy and the deterministic action of a SAC module (evaluation of a
    module straight from a GPU Learner): inputs on the module's device, numpy back out."""
    import gymnasium as gym
    from ray.rllib.algorithms.sac import SACConfig

    import game_env
    from rllib_asor.evaluation.rollout import deterministic_action, module_policy
    from tests.race.test_net import build, obs_batch

    env = gym.make(game_env.ENV_ID, map_id=0)
    try:
        torch.manual_seed(0)
        race_module = build(env)
        batch = obs_batch(env, n=4)
    finally:
        env.close()
    numpy_batch = {k: np.asarray(v) for k, v in batch.items()}
    act = module_policy(race_module, explore=False)
    expected = act(numpy_batch, [])
    with torch.device("meta"):
        np.testing.assert_array_equal(act(numpy_batch, []), expected)

    pendulum = gym.make("Pendulum-v1")
    sac_module = SACConfig().environment("Pendulum-v1").get_rl_module_spec(
        env=pendulum
    ).build()
    obs = pendulum.observation_space.sample()
    expected = deterministic_action(sac_module, obs)
    with torch.device("meta"):
        np.testing.assert_array_equal(deterministic_action(sac_module, obs), expected)
