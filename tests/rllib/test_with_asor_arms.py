"""`with_asor(config)` adds ASOR and nothing else.

For PPO, SAC, CQL, FastSAC and ESCP the two arms, `config` and `with_asor(config)`, build the
same policy module class with the same parameters (critics included), the same replay buffer
and the same update rhythm; the ASOR Learner is a subclass of the base Learner; every other
setting compares equal. Learners are built in this process (no Ray); one short training run
shows ASOR on RLlib's stock SAC path. `rllib ab` checks its arms the same way.
"""

from __future__ import annotations

import argparse
import math
import textwrap

import gymnasium as gym
import numpy as np
import pytest
from ray.rllib.algorithms.cql import CQLConfig
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.algorithms.ppo.torch.ppo_torch_learner import PPOTorchLearner
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.algorithms.sac.torch.default_sac_torch_rl_module import DefaultSACTorchRLModule
from ray.rllib.algorithms.sac.torch.sac_torch_learner import SACTorchLearner
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.rl_module.rl_module import RLModuleSpec

from rllib_asor import EscpConfig, FastSACConfig, with_asor
from rllib_asor.algorithms.ppo.lean import LeanPPOTorchLearner
from rllib_asor.algorithms.sac.config import FastSAC
from rllib_asor.algorithms.sac.fast import FAST_KEY, FastSACTorchRLModule
from rllib_asor.algorithms.sac.learner import FastSACTorchLearner
from rllib_asor.rllib.learners import (
    AsorFastSACTorchLearner,
    AsorPPOTorchLearner,
    AsorSACTorchLearner,
    is_aux_module,
)
from rllib_asor.rllib.wiring import (
    ADDED_KEYS,
    arm_differences,
    asor_learner_class,
)

OBS = gym.spaces.Box(-10, 10, (3,), np.float32)
ACT = gym.spaces.Box(-1, 1, (1,), np.float32)
SMALL_NETS = {"fcnet_hiddens": [16]}
ASOR = {"disc_hiddens": [8], "rnd_hiddens": [8], "rnd_embedding_dim": 4, "seed": 0}


def _small(config):
    return (
        config.environment(observation_space=OBS, action_space=ACT)
        .rl_module(model_config=SMALL_NETS)
        .training(train_batch_size_per_learner=32)
        .debugging(seed=0)
    )


ARMS = {
    "PPO": lambda: (
        PPOConfig()
        .environment("CartPole-v1")
        .rl_module(model_config=SMALL_NETS)
        .training(train_batch_size_per_learner=64, minibatch_size=16, num_epochs=2)
    ),
    "SAC": lambda: _small(SACConfig()),  # RLlib's own SAC: prioritized replay, 1 step/call
    "CQL": lambda: _small(CQLConfig()),
    "FastSAC": lambda: _small(FastSACConfig()),
    "ESCP": lambda: _small(EscpConfig()).escp(history_len=4),
}


def runs(config):
    """The config an algorithm built from `config` runs (FastSAC and ESCP apply their fast
    path when built)."""
    return config.on_fast_path() if hasattr(config, "on_fast_path") else config


def same(x, y) -> bool:
    try:
        return bool(x == y)
    except Exception:
        return repr(x) == repr(y)


def spaces(name: str) -> dict:
    if name == "PPO":
        env = gym.make("CartPole-v1")
        return {DEFAULT_MODULE_ID: (env.observation_space, env.action_space)}
    return {DEFAULT_MODULE_ID: (OBS, ACT)}


RHYTHM = (
    "train_batch_size_per_learner",
    "minibatch_size",
    "num_epochs",
    "training_intensity",
    "rollout_fragment_length",
    "num_steps_sampled_before_learning_starts",
    "n_step",
    "tau",
    "target_network_update_freq",
    "replay_buffer_config",
)


@pytest.mark.parametrize("name", list(ARMS))
def test_the_arms_differ_only_in_what_asor_adds(name):
    base = ARMS[name]()
    treated = with_asor(base, **ASOR)

    # every setting but the ones with_asor sets compares equal
    a, b = base.to_dict(), treated.to_dict()
    changed = {k for k in a.keys() | b.keys() if not same(a.get(k), b.get(k))}
    assert changed <= set(ADDED_KEYS), changed - set(ADDED_KEYS)
    assert {k: v for k, v in treated.learner_config_dict.items() if k != "asor"} == (
        base.learner_config_dict
    )
    assert treated.learner_config_dict["asor"]["disc_hiddens"] == [8]
    assert arm_differences(base, treated) == []

    # the ASOR Learner is the base Learner plus ASOR
    assert treated.learner_class is not base.learner_class
    assert issubclass(treated.learner_class, base.learner_class)
    # ... and nothing else: ASOR's mixin directly on that Learner, no speed-ups of its own
    assert treated.learner_class.__bases__[-1] is base.learner_class

    # what the built algorithms run: the same replay buffer and update rhythm
    ran_base, ran_treated = runs(base), runs(treated)
    for attr in RHYTHM:
        assert same(getattr(ran_treated, attr, None), getattr(ran_base, attr, None)), attr
    lcd = {k: v for k, v in ran_treated.learner_config_dict.items() if k != "asor"}
    assert lcd == ran_base.learner_config_dict
    assert issubclass(ran_treated.learner_class, ran_base.learner_class)

    # the Learners: the same policy module class, the same parameters (critics included);
    # ASOR's modules beside it
    learner_base = ran_base.build_learner(spaces=spaces(name))
    learner_treated = ran_treated.build_learner(spaces=spaces(name))
    assert isinstance(learner_treated, type(learner_base))
    policy_base = learner_base.module[DEFAULT_MODULE_ID].unwrapped()
    policy_treated = learner_treated.module[DEFAULT_MODULE_ID].unwrapped()
    assert type(policy_treated) is type(policy_base)
    shapes = {k: tuple(v.shape) for k, v in policy_base.state_dict().items()}
    assert {k: tuple(v.shape) for k, v in policy_treated.state_dict().items()} == shapes
    added = set(learner_treated.module.keys()) - set(learner_base.module.keys())
    assert added and all(is_aux_module(m) for m in added)
    assert set(learner_base.module.keys()) <= set(learner_treated.module.keys())


def test_stock_and_fast_sac_keep_their_own_module_buffer_and_rhythm():
    """The two SAC arms are what their configs say: RLlib's SAC stays RLlib's (its
    multi-stream critics, prioritized buffer, one gradient step per Learner call); FastSAC's
    both arms get the concat-MLP critics, the flat buffer and 16 steps per call."""
    stock = with_asor(ARMS["SAC"]())
    assert stock.learner_class is AsorSACTorchLearner
    assert stock.replay_buffer_config["type"] == "PrioritizedEpisodeReplayBuffer"
    assert FAST_KEY not in stock.learner_config_dict
    module = stock.get_multi_rl_module_spec(spaces=spaces("SAC")).rl_module_specs
    assert module[DEFAULT_MODULE_ID].module_class is DefaultSACTorchRLModule
    assert stock.train_batch_size_per_learner == 32 and stock.rollout_fragment_length == "auto"

    for fast in (ARMS["FastSAC"]().on_fast_path(), with_asor(ARMS["FastSAC"]()).on_fast_path()):
        assert fast.algo_class is FastSAC and fast.learner_config_dict[FAST_KEY] is True
        assert fast.replay_buffer_config["storage"] == "flat"
        specs = fast.get_multi_rl_module_spec(spaces=spaces("SAC")).rl_module_specs
        assert specs[DEFAULT_MODULE_ID].module_class is FastSACTorchRLModule
        assert fast.train_batch_size_per_learner > 32 and fast.rollout_fragment_length != "auto"
    assert with_asor(ARMS["FastSAC"]()).learner_class is AsorFastSACTorchLearner


def test_arm_differences_names_what_else_changed():
    base = ARMS["FastSAC"]()
    assert arm_differences(base, with_asor(base.copy().training(gamma=0.5))) == ["gamma"]
    other_module = with_asor(
        base.copy().rl_module(rl_module_spec=RLModuleSpec(module_class=DefaultSACTorchRLModule))
    )
    assert arm_differences(base, other_module) == ["rl_module_spec"]
    swapped = with_asor(base).learners(learner_class=AsorSACTorchLearner)  # not a FastSAC one
    assert arm_differences(base, swapped) == ["learner_class"]
    more = with_asor(base).learners(learner_config_dict={"fast_off_policy_minibatch": 8})
    assert arm_differences(base, more) == ["learner_config_dict"]


def test_arm_differences_names_each_kind_of_setting_beyond_asor():
    from ray.rllib.callbacks.callbacks import RLlibCallback

    class UserCallback(RLlibCallback):
        pass

    base = ARMS["PPO"]()
    assert arm_differences(base, with_asor(base)) == []
    assert arm_differences(base, with_asor(base).learners(learner_class=LeanPPOTorchLearner)) == [
        "learner_class"
    ]
    assert arm_differences(base, with_asor(base).callbacks(UserCallback)) == ["callbacks"]
    assert arm_differences(base, with_asor(base).multi_agent(policies_to_train=["x"])) == [
        "policies_to_train"
    ]
    # the user's own learner_config_dict, callbacks and policies_to_train kept by with_asor
    own = (
        base.copy()
        .learners(learner_config_dict={"x": 1})
        .callbacks(UserCallback)
        .multi_agent(policies_to_train=[DEFAULT_MODULE_ID])
    )
    assert arm_differences(own, with_asor(own)) == []
    assert arm_differences(own, with_asor(base)) == [
        "learner_config_dict",
        "callbacks",
        "policies_to_train",
    ]
    # settings only one config class has are named too
    assert "twin_q" in arm_differences(base, with_asor(ARMS["SAC"]()))
    # values == cannot compare (arrays) are compared by what they print
    arrays = base.copy().environment(env_config={"a": np.arange(3)})
    assert arm_differences(arrays, with_asor(arrays)) == []
    other = with_asor(base.copy().environment(env_config={"a": np.arange(4)}))
    assert arm_differences(arrays, other) == ["env_config"]
    # multi-agent: each policy's module spec, a policy more is a spec more
    def mapping(agent_id, *args, **kwargs):
        return agent_id

    two = base.copy().multi_agent(policies={"p0", "p1"}, policy_mapping_fn=mapping)
    three = base.copy().multi_agent(policies={"p0", "p1", "p2"}, policy_mapping_fn=mapping)
    assert arm_differences(two, with_asor(two)) == []
    assert arm_differences(two, with_asor(three)) == ["policies", "rl_module_spec"]
    # a policy spec that only names the default module class is the default
    default = base.get_default_rl_module_spec().module_class
    named = base.copy().rl_module(rl_module_spec=RLModuleSpec(module_class=default))
    assert arm_differences(base, with_asor(named)) == []


def test_the_asor_learner_subclasses_the_users_learner_or_refuses():
    assert asor_learner_class(PPOConfig()) is AsorPPOTorchLearner
    lean = asor_learner_class(PPOConfig().learners(learner_class=LeanPPOTorchLearner))
    assert lean.__bases__[-1] is LeanPPOTorchLearner
    sac = SACConfig().learners(learner_class=FastSACTorchLearner)
    assert asor_learner_class(sac) is AsorFastSACTorchLearner

    class MyAsorSAC(AsorSACTorchLearner):
        pass

    assert asor_learner_class(SACConfig().learners(learner_class=MyAsorSAC)) is MyAsorSAC

    class MySAC(SACTorchLearner):
        def compute_loss_for_module(self, *args, **kwargs):
            return super().compute_loss_for_module(*args, **kwargs)

    with pytest.raises(ValueError, match="learner_class=MySAC has no ASOR Learner"):
        with_asor(SACConfig().learners(learner_class=MySAC))
    assert issubclass(asor_learner_class(PPOConfig()), PPOTorchLearner)

    # moving an ASOR config onto another Learner keeps ASOR (drop_bootstrap_rows does this)
    assert AsorPPOTorchLearner.asor_learner_on(LeanPPOTorchLearner) is lean
    with pytest.raises(ValueError, match="no ASOR Learner on MySAC; allowed: PPOTorchLearner, "):
        AsorPPOTorchLearner.asor_learner_on(MySAC)


def test_per_dynamics_rnd_is_refused_on_the_flat_buffer_only():
    with pytest.raises(ValueError, match="proxy='rnd_per_dynamics' needs each step's dynamics"):
        with_asor(FastSACConfig(), proxy="rnd_per_dynamics")
    stock = with_asor(SACConfig(), proxy="rnd_per_dynamics")  # RLlib's replay keeps infos
    assert stock.learner_class is AsorSACTorchLearner
    with_asor(FastSACConfig(), mode="srpo", proxy="rnd_per_dynamics")  # srpo: no proxy


def test_asor_trains_on_rllibs_stock_sac(ray_session):
    """`with_asor(SACConfig())`: RLlib's own SAC module, Learner pipeline and replay buffer,
    one gradient step per env step, with ASOR's piece in the Learner connector."""
    config = (
        SACConfig()
        .environment("Pendulum-v1")
        .env_runners(num_env_runners=0)
        .rl_module(model_config={"fcnet_hiddens": [32]})
        .training(
            train_batch_size_per_learner=32,
            num_steps_sampled_before_learning_starts=64,
            replay_buffer_config={"capacity": 2000},
        )
        .reporting(min_sample_timesteps_per_iteration=64)
        .debugging(seed=0)
    )
    algo = with_asor(config, lambda_=0.05, **ASOR).build_algo()
    try:
        learner = algo.learner_group._learner
        assert type(learner) is AsorSACTorchLearner
        assert type(learner.module[DEFAULT_MODULE_ID].unwrapped()) is DefaultSACTorchRLModule
        assert type(algo.local_replay_buffer).__name__ == "PrioritizedEpisodeReplayBuffer"
        calls = []
        update = learner._update
        learner._update = lambda batch, **kw: calls.append(1) or update(batch, **kw)
        for _ in range(2):
            result = algo.train()
        # stock rhythm: one gradient step of batch 32 per sampled env step after warm-up
        assert len(calls) == result["num_env_steps_sampled_lifetime"] - 64 + 1
        assert math.isfinite(result["asor"]["disc_loss"])
        assert math.isfinite(result["learners"][DEFAULT_MODULE_ID]["qf_loss"])
    finally:
        algo.stop()


# ------------------------------------------------------------------ the CLI: run: FastSAC, ab
SAC_FILE = """
pendulum-sac-asor:
  env: Pendulum-v1
  run: {run}
  stop: {{training_iteration: 1}}
  config:
    train_batch_size_per_learner: 32
    num_steps_sampled_before_learning_starts: 64
    replay_buffer_config: {{type: EpisodeReplayBuffer, capacity: 2000}}
    model_config: {{fcnet_hiddens: [16]}}
    num_env_runners: 0
{extra}    asor: {{mode: asor, seed: 0}}
"""


def _ab_args(path, vs=None) -> argparse.Namespace:
    return argparse.Namespace(
        file=str(path),
        seeds=2,
        vs=vs,
        episodes=1,
        eval_interval=None,
        name=None,
        storage_path=None,
        test=False,
        num_env_runners=0,
        stop=None,
    )


@pytest.mark.parametrize("run", ["SAC", "FastSAC"])
def test_rllib_ab_arms_differ_only_in_asor(run, tmp_path, capsys):
    from rllib_asor.cli import ab

    path = tmp_path / "sac.yaml"
    path.write_text(textwrap.dedent(SAC_FILE.format(run=run, extra="")))
    named = ab.prepared_arms(_ab_args(path))
    assert [name for name, _, _ in named] == [run, f"{run}+ASOR"]
    assert ab.arm_check(named, vs=False).endswith(
        "the arms differ only in ASOR " + ("(same module, replay, critics and rhythm)")
    )
    for _, _, cfg in named:  # run: SAC keeps choosing the fast path, for both arms
        assert cfg.learner_config_dict[FAST_KEY] is True
        assert cfg.replay_buffer_config["storage"] == "flat"
    if run == "SAC":
        assert capsys.readouterr().err.count("runs on the fast off-policy path") <= 1

    vs = tmp_path / "other.yaml"
    vs.write_text(textwrap.dedent(SAC_FILE.format(run=run, extra="    gamma: 0.9\n")))
    text = vs.read_text().replace("    asor: {mode: asor, seed: 0}\n", "")
    vs.write_text(text)
    named = ab.prepared_arms(_ab_args(path, vs=str(vs)))
    assert ab.arm_check(named, vs=True) == "rllib ab: besides ASOR, the arms differ in: gamma"


def test_rllib_ab_keeps_rllibs_replay_for_both_arms_of_per_dynamics_rnd(tmp_path):
    from rllib_asor.cli import ab

    path = tmp_path / "sac.yaml"
    text = SAC_FILE.format(run="SAC", extra="").replace(
        "{mode: asor, seed: 0}", "{mode: asor, proxy: rnd_per_dynamics, seed: 0}"
    )
    path.write_text(textwrap.dedent(text))
    named = ab.prepared_arms(_ab_args(path))
    for _, _, cfg in named:
        assert cfg.learner_config_dict[FAST_KEY] is False
        assert "storage" not in cfg.replay_buffer_config
    assert "differ only in ASOR" in ab.arm_check(named, vs=False)
