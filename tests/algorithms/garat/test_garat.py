"""GARAT: the grounding MDP and the grounded env on hand-checked steps, GARAT on Pendulum
(grounding, PPO in the grounded source, evaluation in the target; with ASOR; checkpoint round
trip without grounding again; two Learners; a GPU) and bad input in one line. The transformer's
reward and loss are GAIfO's (tests/algorithms/gaifo)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

import rllib_asor
from rllib_asor.algorithms.common.demonstrations import rollout_demonstrations, save_demonstrations
from rllib_asor.algorithms.garat.config import GaratConfig
from rllib_asor.algorithms.garat.envs import GroundedEnv, GroundingEnv

pytestmark = pytest.mark.heavy  # starts Ray or a subprocess: scheduled first (conftest)

SOURCE, TARGET = {"g": 10.0}, {"g": 12.0}


@pytest.fixture(scope="module")
def target_data(tmp_path_factory) -> str:
    rng = np.random.default_rng(0)
    demos = rollout_demonstrations(
        lambda o: rng.uniform(-2, 2, 1).astype(np.float32), "Pendulum-v1", 3, env_kwargs=TARGET
    )
    path = tmp_path_factory.mktemp("garat") / "pendulum-g12.npz"
    save_demonstrations(path, demos)
    return str(path)


def tiny_garat(target_data: str) -> GaratConfig:
    """GARAT on Pendulum, one small grounding iteration (also the GPU test's setup)."""
    return (
        GaratConfig()
        .environment("Pendulum-v1", env_config=SOURCE)
        .env_runners(num_env_runners=0)
        .training(train_batch_size=200, minibatch_size=100, num_epochs=1)
        .rl_module(model_config={"fcnet_hiddens": [16]})
        .garat(
            demonstrations=target_data,
            target_env_config=TARGET,
            grounding_iterations=1,
            grounding_batch_size=200,
            transformer_hiddens=[16],
            disc_hiddens=[16],
        )
        .evaluation(evaluation_interval=1, evaluation_duration=1)
        .debugging(seed=0)
    )


def _wraps(env, cls) -> bool:
    """Whether `cls` is somewhere in the env runner's env's wrapper chain."""
    while env is not None:
        if isinstance(env, cls):
            return True
        env = getattr(env, "env", None) or (getattr(env, "envs", None) or [None])[0]
    return False


def _gravity(env) -> float:
    while not hasattr(env.unwrapped, "g"):
        env = getattr(env.unwrapped, "env", None) or env.unwrapped.envs[0]
    return env.unwrapped.g


# ----------------------------------------------------------------------------- the envs
def test_grounding_env_observes_s_and_the_behaviour_action_and_plays_their_clipped_sum():
    env = GroundingEnv({"env": "Pendulum-v1", "env_config": SOURCE, "action_tf_ratio": 2.0})
    plain = gym.make("Pendulum-v1", **SOURCE)
    obs, _ = env.reset(seed=3)
    s, _ = plain.reset(seed=3)
    assert obs.shape == (4,) and np.allclose(obs[:3], s) and -2 <= obs[3] <= 2
    assert env.action_space.high.tolist() == [4.0]  # ratio 2 × half the range 2
    for delta in (0.5, 4.0):  # a + 4 is clipped to the source's +2
        played = np.clip(obs[3] + delta, -2, 2)
        obs, reward, *_ = env.step(np.array([delta], np.float32))
        s, *_ = plain.step(np.array([played], np.float32))
        assert np.allclose(obs[:3], s) and reward == 0.0


def test_grounding_env_plays_a_deterministic_behaviour_policy_when_given():
    pi0 = lambda obs: np.array([obs[2] / 4.0], np.float32)  # noqa: E731  (θ̇/4, clipped to ±2)
    config = {"env": "Pendulum-v1", "env_config": SOURCE, "behaviour": pi0}
    env = GroundingEnv(config)
    obs, _ = env.reset(seed=0)
    for _ in range(5):
        assert obs[3] == pytest.approx(np.clip(obs[2] / 4.0, -2, 2))
        obs, *_ = env.step(np.zeros(1, np.float32))


def delta_one_transformer():
    """A PPO module for the grounding MDP (obs (s, a), Δ ∈ [-4, 4]) whose mean Δ is 1
    everywhere: every weight 0, the mean head's bias 1. Returns (spec, module)."""
    from ray.rllib.algorithms.ppo.torch.default_ppo_torch_rl_module import (
        DefaultPPOTorchRLModule,
    )
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    spec = RLModuleSpec(
        module_class=DefaultPPOTorchRLModule,
        observation_space=gym.spaces.Box(-10, 10, (4,), np.float32),
        action_space=gym.spaces.Box(-4, 4, (1,), np.float32),
        model_config={"fcnet_hiddens": [4]},
    )
    module = spec.build()
    with torch.no_grad():
        for name, p in module.named_parameters():
            p.zero_()
            if name.startswith("pi.") and name.endswith("bias"):
                p[0] = 1.0
    return spec, module


def test_grounded_env_plays_a_plus_delta_and_without_a_transformer_is_the_source():
    spec, module = delta_one_transformer()
    saved = {"spec": spec, "state": module.get_state()}
    plain = GroundedEnv({"env": "Pendulum-v1", "env_config": SOURCE})
    grounded = GroundedEnv({"env": "Pendulum-v1", "env_config": SOURCE, "transformer": saved})
    ref = gym.make("Pendulum-v1", **SOURCE)
    for e in (plain, grounded, ref):
        e.reset(seed=1)
    a = np.array([0.5], np.float32)
    s_plain, s_grounded = plain.step(a)[0], grounded.step(a)[0]
    assert np.allclose(s_plain, ref.step(a)[0])
    ref.reset(seed=1)
    assert np.allclose(s_grounded, ref.step(np.array([1.5], np.float32))[0])  # 0.5 + 1


# ----------------------------------------------------------------------------- RLlib
def test_garat_grounds_trains_in_the_grounded_source_and_evaluates_in_the_target(
    target_data, tmp_path
):
    algo = tiny_garat(target_data).build_algo()
    try:
        assert _wraps(algo.env_runner.env, GroundedEnv)
        assert not _wraps(algo.eval_env_runner.env.unwrapped.envs[0], GroundedEnv) or (
            algo.eval_env_runner.config.env_config["transformer"] is None
        )
        assert _gravity(algo.env_runner.env) == 10.0 and _gravity(algo.eval_env_runner.env) == 12.0
        result = algo.train()
        assert np.isfinite(result["garat"]["grounding_disc_loss"])
        assert np.isfinite(result["evaluation"]["env_runners"]["episode_return_mean"])
        grounded = algo.config.garat_grounded
        assert repr(grounded["transformer"]).startswith("SavedTransformer(")  # no weights in logs
        checkpoint = algo.save_to_path(str(tmp_path / "ckpt"))
        weights = algo.get_module().get_state()
        algo.get_module().save_to_path(str(tmp_path / "pi0"))
    finally:
        algo.stop()
    restored = type(algo).from_checkpoint(checkpoint)  # no second grounding: the same Δ
    try:
        again = restored.config.garat_grounded
        for k, v in grounded["transformer"]["state"].items():
            np.testing.assert_array_equal(again["transformer"]["state"][k], v, err_msg=k)
        for k, v in weights.items():
            np.testing.assert_array_equal(restored.get_module().get_state()[k], v, err_msg=k)
    finally:
        restored.stop()
    # π₀ as the behaviour policy: the agent starts from its weights (the authors' initial policy)
    config = tiny_garat(target_data).garat(behaviour_policy=str(tmp_path / "pi0"))
    started = config.build_algo()
    try:
        for k, v in weights.items():
            np.testing.assert_array_equal(started.get_module().get_state()[k], v, err_msg=k)
    finally:
        started.stop()


@pytest.mark.slow  # two Learner actors; GAIfO's discriminator on two Learners:
# tests/algorithms/gaifo (test_two_learners_keep_one_discriminator), PPO+ASOR: tests/cluster
def test_garat_with_asor_and_two_learners_trains(target_data):
    config = tiny_garat(target_data).learners(num_learners=2, num_cpus_per_learner=0.5)
    algo = rllib_asor.with_asor(config, seed=0).build_algo()
    try:
        result = algo.train()
        assert np.isfinite(result["asor"]["disc_loss"])
    finally:
        algo.stop()


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_garat_trains_on_a_gpu(target_data):
    algo = tiny_garat(target_data).learners(num_gpus_per_learner=1).build_algo()
    try:
        assert np.isfinite(algo.train()["evaluation"]["env_runners"]["episode_return_mean"])
    finally:
        algo.stop()


# ----------------------------------------------------------------------------- bad input
def test_bad_input_is_one_line_naming_the_problem(tmp_path, target_data):
    with pytest.raises(ValueError, match="garat.alpha=-1 is not allowed; expected a number ≥ 0"):
        GaratConfig().garat(alpha=-1)
    config = GaratConfig().environment("Pendulum-v1")
    with pytest.raises(ValueError, match="GARAT needs the target's transitions"):
        config.validate()
    with pytest.raises(ValueError, match="garat.behaviour_policy .*nope does not exist"):
        config.garat(demonstrations=target_data, behaviour_policy="nope").validate()
    with pytest.raises(ValueError, match="GARAT needs the source env as a registered id"):
        GaratConfig().environment(GroundingEnv).garat(demonstrations="x.npz").validate()
    wrong = tmp_path / "lava.npz"
    obs = np.zeros((4, 15), np.float32)
    from rllib_asor.algorithms.common.demonstrations import Demonstrations

    save_demonstrations(wrong, Demonstrations.of(obs, obs, np.zeros(4), np.zeros(4, bool)))
    with pytest.raises(ValueError, match=r"expected \(3,\).*got \(15,\)"):
        config.garat(demonstrations=str(wrong)).validate()
