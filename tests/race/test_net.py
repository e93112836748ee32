"""RaceNetModule on the race's real spaces: shapes, valid actions, gradients, settings."""

import copy

import gymnasium as gym
import numpy as np
import pytest
import torch
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.rl_module import RLModuleSpec

import game_env
from rllib_asor.race.net import DEFAULTS, RaceNetModule
from rllib_asor.registry.models import MODULES, get_module_class

B = 8


@pytest.fixture(scope="module")
def env():
    env = gym.make(game_env.ENV_ID, map_id=0)
    yield env
    env.close()


def build(env, **model_config):
    return RaceNetModule(
        observation_space=env.observation_space,
        action_space=env.action_space,
        model_config=model_config,
    )


def obs_batch(env, n=B, seed=0):
    """n observations: half sampled from the space, half from real env steps."""
    env.observation_space.seed(seed)
    samples = [env.observation_space.sample() for _ in range(n // 2)]
    obs, _ = env.reset(seed=seed)
    env.action_space.seed(seed)
    while len(samples) < n:
        samples.append(obs)
        obs, *_ = env.step(env.action_space.sample())
    return {k: torch.as_tensor(np.stack([s[k] for s in samples])) for k in env.observation_space}


def test_forward_gives_valid_actions_for_all_eight_heads_and_values_of_shape_b(env):
    module = build(env)
    batch = {Columns.OBS: obs_batch(env)}
    nvec = list(env.action_space.nvec)
    for out in (module.forward_inference(batch), module.forward_exploration(batch)):
        logits = out[Columns.ACTION_DIST_INPUTS]
        assert logits.shape == (B, sum(nvec)) and torch.isfinite(logits).all()
        dist = module.get_exploration_action_dist_cls().from_logits(logits)
        actions = dist.sample()
        assert actions.shape == (B, len(nvec))
        for a in actions.numpy():
            assert env.action_space.contains(a.astype(env.action_space.dtype))
        assert dist.logp(actions).shape == (B,)
        greedy = module.get_inference_action_dist_cls().from_logits(logits).to_deterministic()
        assert greedy.sample().shape == (B, len(nvec))
    values = module.compute_values(batch)
    assert values.shape == (B,) and torch.isfinite(values).all()


def test_acting_switches_to_eval_once_and_training_switches_back(env):
    module = build(env)
    batch = {Columns.OBS: obs_batch(env)}
    assert module.training  # a new torch module trains
    trained = module.forward_train(batch)[Columns.ACTION_DIST_INPUTS]
    acted = module.forward_exploration(batch)[Columns.ACTION_DIST_INPUTS]
    assert not module.training and not any(m.training for m in module.modules())
    # Same weights, same logits: the mode changes no result (attention's fused path only).
    torch.testing.assert_close(acted, trained.detach(), rtol=1e-4, atol=1e-5)
    module.forward_inference(batch)
    assert not module.training
    module.forward_train(batch)
    assert module.training and all(m.training for m in module.modules())


def test_acting_without_autograd_runs_a_trace_with_the_eager_logits_and_new_weights(env):
    """What an env runner does: acting under no_grad, weights synced in place between calls."""
    module = build(env)
    eager = build(env, trace_inference=False)
    eager.load_state_dict(module.state_dict())

    def both_act(n: int, seed: int) -> None:
        batch = {Columns.OBS: obs_batch(env, n, seed)}
        with torch.no_grad():
            got = module.forward_exploration(batch)[Columns.ACTION_DIST_INPUTS]
            want = eager.forward_exploration(batch)[Columns.ACTION_DIST_INPUTS]
        assert torch.equal(got, want)  # bit for bit: the same actions from the same seeds

    module.forward_train({Columns.OBS: obs_batch(env)})  # training: eager, with autograd
    assert "_trace" not in module.__dict__
    for n in (1, 8, 31):  # one trace (made at 1 row) serves every batch size
        both_act(n, seed=n)
    assert module.__dict__["_trace"][1] is not None and "_trace" not in eager.__dict__
    moved = {k: v + 0.01 for k, v in module.get_state().items()}
    module.set_state(moved)
    eager.set_state(moved)
    both_act(8, seed=1)
    assert module.state_dict().keys() == eager.state_dict().keys()  # the trace is no state
    twin = copy.deepcopy(module)  # a copy traces its own parameters when it acts
    assert "_trace" not in twin.__dict__
    with torch.no_grad():
        batch = {Columns.OBS: obs_batch(env)}
        torch.testing.assert_close(
            twin.forward_exploration(batch)[Columns.ACTION_DIST_INPUTS],
            module.forward_exploration(batch)[Columns.ACTION_DIST_INPUTS],
        )


@pytest.mark.parametrize("share", [True, False])
def test_gradients_reach_every_parameter(env, share):
    module = build(env, vf_share_encoders=share)
    batch = {Columns.OBS: obs_batch(env)}
    out = module.forward_train(batch)
    dist = module.get_train_action_dist_cls().from_logits(out[Columns.ACTION_DIST_INPUTS])
    actions = dist.sample()
    values = module.compute_values(batch, embeddings=out.get(Columns.EMBEDDINGS))
    (-dist.logp(actions).mean() - 0.01 * dist.entropy().mean() + values.pow(2).mean()).backward()
    dead = [n for n, p in module.named_parameters() if p.grad is None or not p.grad.abs().sum()]
    assert not dead, f"no gradient: {dead}"
    assert (Columns.EMBEDDINGS in out) == share


def test_default_size_is_small_and_model_config_changes_it(env):
    n_default = sum(p.numel() for p in build(env).parameters())
    assert 50_000 < n_default <= 200_000
    bigger = build(env, cnn_channels=[16, 32, 32], pi_hiddens=[256, 128], attn_token_size=1)
    assert sum(p.numel() for p in bigger.parameters()) != n_default
    assert bigger.forward_inference({Columns.OBS: obs_batch(env)})[
        Columns.ACTION_DIST_INPUTS
    ].shape == (B, 24)


@pytest.mark.parametrize(
    "bad",
    [{"cnn_channels": []}, {"attn_heads": 5}, {"pi_hiddens": "128"}, {"vf_share_encoders": 1},
     {"trace_inference": "yes"}],  # fmt: skip
)
def test_bad_model_config_is_a_value_error_naming_the_key(env, bad):
    with pytest.raises(ValueError, match=f"{next(iter(bad))}=.*allowed"):
        build(env, **bad)


def test_wrong_spaces_are_rejected(env):
    with pytest.raises(ValueError, match="Dict observation space"):
        RaceNetModule(
            observation_space=gym.spaces.Box(-1, 1, (3,)),
            action_space=env.action_space,
            model_config={},
        )
    with pytest.raises(ValueError, match="MultiDiscrete"):
        RaceNetModule(
            observation_space=env.observation_space,
            action_space=gym.spaces.Discrete(3),
            model_config={},
        )


def test_spec_build_ignores_rllib_default_model_keys(env):
    spec = RLModuleSpec(
        module_class=get_module_class("race_net"),
        observation_space=env.observation_space,
        action_space=env.action_space,
        model_config={"fcnet_hiddens": [7], "vf_share_layers": True, "pi_hiddens": [64]},
    )
    module = spec.build()
    assert module.settings["pi_hiddens"] == [64]
    assert module.settings["cnn_channels"] == DEFAULTS["cnn_channels"]


def test_registry_resolves_names_and_dotted_paths():
    assert get_module_class("race_net") is RaceNetModule
    assert get_module_class("rllib_asor.race.net:RaceNetModule") is RaceNetModule
    assert get_module_class("rllib_asor.race.net.RaceNetModule") is RaceNetModule
    assert set(MODULES) == {"race_net"}
    for bad in ("race_nett", "rllib_asor.race.net:Nope", "no_such_pkg.mod:X", ""):
        with pytest.raises(ValueError, match="race_net"):
            get_module_class(bad)
