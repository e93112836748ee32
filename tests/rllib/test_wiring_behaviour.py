"""How `with_asor`, the `Asor<run>` Tune trainables and the metrics callback wire ASOR into an
RLlib config, checked in this process on configs, module specs and hand-made results (no Ray
started): the learner class, the stored settings, the base algorithm's path kept, one
discriminator (and proxy) per trained policy with that policy's spaces, `policies_to_train` that
always trains the aux modules, the `"asor"` block of a Tune config dict, and `asor/...` in the
results."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from ray.rllib.algorithms.algorithm_config import AlgorithmConfig
from ray.rllib.algorithms.cql import CQL, CQLConfig
from ray.rllib.algorithms.dqn import DQNConfig
from ray.rllib.algorithms.impala import IMPALAConfig
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.algorithms.ppo.torch.default_ppo_torch_rl_module import DefaultPPOTorchRLModule
from ray.rllib.algorithms.sac import SAC, SACConfig
from ray.rllib.callbacks.callbacks import RLlibCallback
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.rl_module.multi_rl_module import MultiRLModule
from ray.rllib.core.rl_module.rl_module import RLModuleSpec
from ray.rllib.policy.policy import PolicySpec

from rllib_asor.algorithms.escp.config import EscpConfig
from rllib_asor.algorithms.maple.maple import MapleConfig, MopoConfig
from rllib_asor.algorithms.ppo.overlap import OverlappedPPO
from rllib_asor.algorithms.sac.config import FastSACConfig
from rllib_asor.algorithms.sac.fast import (
    FAST_KEY,
    FastCQLTorchRLModule,
    FastSACTorchRLModule,
    fast_off_policy,
)
from rllib_asor.asor.config import AsorConfig
from rllib_asor.cli import experiment
from rllib_asor.registry import envs
from rllib_asor.rllib import trainable
from rllib_asor.rllib.callbacks import AsorMetricsCallback, lift_asor_metrics
from rllib_asor.rllib.learners import (
    AsorCQLTorchLearner,
    AsorESCPTorchLearner,
    AsorFastSACTorchLearner,
    AsorMapleTorchLearner,
    AsorPPOTorchLearner,
    AsorSACTorchLearner,
    asor_module_id,
)
from rllib_asor.rllib.modules import AsorModule
from rllib_asor.rllib.trainable import _asor_init, asor_trainable
from rllib_asor.rllib.wiring import (
    SUPPORTED,
    AsorMultiRLModuleSpec,
    _algorithm_name,
    _AlsoTrainAux,
    trained_policy_ids,
    with_asor,
)

OBS = gym.spaces.Box(-1, 1, (3,), np.float32)
ACT = gym.spaces.Discrete(2)
OBS_B = gym.spaces.Box(-5, 5, (4,), np.float32)
ACT_B = gym.spaces.Discrete(3)
SMALL = {"disc_hiddens": [8], "rnd_hiddens": [8], "rnd_embedding_dim": 4, "seed": 0}
SETTINGS = {"lambda_": 0.3, "seed": 7}
DISC = asor_module_id(DEFAULT_MODULE_ID)


def stored(**settings) -> dict:
    """What `learner_config_dict["asor"]` (and each aux module's model_config) should hold."""
    return AsorConfig.from_dict(settings).to_dict()


def ppo() -> PPOConfig:
    return PPOConfig().environment(observation_space=OBS, action_space=ACT)


def two_policies(**multi_agent) -> PPOConfig:
    """Policies "a" (spaces OBS/ACT) and "b" (OBS_B/ACT_B), in that order."""
    return PPOConfig().multi_agent(
        policies={
            "a": PolicySpec(observation_space=OBS, action_space=ACT),
            "b": PolicySpec(observation_space=OBS_B, action_space=ACT_B),
        },
        policy_mapping_fn=lambda agent_id, *args, **kwargs: "a",
        **multi_agent,
    )


def specs(config: AlgorithmConfig) -> dict[str, RLModuleSpec]:
    return config._rl_module_spec.rl_module_specs


class UserCallback(RLlibCallback):
    pass


# ------------------------------------------------------------------ with_asor
def test_with_asor_returns_a_wired_copy_and_leaves_the_users_config_alone():
    config = ppo().learners(learner_config_dict={"mine": 1}).callbacks(UserCallback)
    out = with_asor(config, **SETTINGS)
    assert out is not config
    assert out.learner_class is AsorPPOTorchLearner
    assert out.learner_config_dict == {"mine": 1, "asor": stored(**SETTINGS)}
    assert out.callbacks_class == [UserCallback, AsorMetricsCallback]
    assert isinstance(out._rl_module_spec, AsorMultiRLModuleSpec)
    # the input is unchanged
    assert config._learner_class is None
    assert config.learner_config_dict == {"mine": 1}
    assert config.callbacks_class is UserCallback
    assert config._rl_module_spec is None


def test_with_asor_adds_the_metrics_callback_to_a_config_without_callbacks():
    assert with_asor(ppo()).callbacks_class == [AsorMetricsCallback]


def test_a_frozen_config_gives_an_unfrozen_wired_copy():
    config = ppo()
    config.freeze()
    out = with_asor(config, **SETTINGS)
    assert out._is_frozen is False
    assert out.training(lr=0.5).lr == 0.5
    assert config._is_frozen is True


def test_a_named_env_is_registered_for_the_env_runners():
    out = with_asor(PPOConfig().environment("CartPole-v1"))
    assert out.env == "CartPole-v1"
    assert envs.in_tune_registry("CartPole-v1")


@pytest.mark.parametrize(
    "config, learner",
    [
        (PPOConfig(), AsorPPOTorchLearner),
        (PPOConfig(algo_class=OverlappedPPO), AsorPPOTorchLearner),
        (SACConfig(), AsorSACTorchLearner),
        (FastSACConfig(), AsorFastSACTorchLearner),
        (CQLConfig(), AsorCQLTorchLearner),
        (MapleConfig(), AsorMapleTorchLearner),
        (MopoConfig(), AsorMapleTorchLearner),
        (EscpConfig(), AsorESCPTorchLearner),
    ],
    ids=["PPO", "OverlappedPPO", "SAC", "FastSAC", "CQL", "MAPLE", "MOPO", "ESCP"],
)
def test_each_algorithm_gets_its_asor_learner(config, learner):
    assert with_asor(config).learner_class is learner


@pytest.mark.parametrize(
    "config, name",
    [
        (PPOConfig(algo_class=OverlappedPPO), "PPO"),
        (MopoConfig(), "MAPLE"),
        (EscpConfig(), "ESCP"),  # a SAC subclass that is supported itself
        (CQLConfig(), "CQL"),  # likewise
        (DQNConfig(), "DQN"),
        (AlgorithmConfig(), "AlgorithmConfig"),  # no algo_class: the config's class
    ],
)
def test_algorithm_name_is_the_first_supported_class_in_the_algorithms_mro(config, name):
    assert _algorithm_name(config) == name


@pytest.mark.parametrize(
    "config, message",
    [
        ({"lr": 1e-3}, "with_asor needs an RLlib AlgorithmConfig, got dict"),
        (
            DQNConfig(),
            "ASOR does not support algorithm 'DQN': supported CQL, ESCP, MAPLE, PPO, SAC",
        ),
        (IMPALAConfig(), "ASOR does not support algorithm 'IMPALA': supported CQL"),
        (AlgorithmConfig(), "ASOR does not support algorithm 'AlgorithmConfig'"),
        (
            PPOConfig().api_stack(
                enable_rl_module_and_learner=False, enable_env_runner_and_connector_v2=False
            ),
            "ASOR needs RLlib's new API stack",
        ),
        (PPOConfig().framework("tf2"), "ASOR needs framework='torch', got 'tf2'"),
    ],
    ids=["not_a_config", "DQN", "IMPALA", "no_algo_class", "old_api_stack", "tf2"],
)
def test_with_asor_refuses_what_it_cannot_wire(config, message):
    with pytest.raises(ValueError) as err:
        with_asor(config)
    assert message in str(err.value)


# ------------------------------------------------------------------ the base algorithm's path
@pytest.mark.parametrize(
    "config, settings",
    [
        (SACConfig(), {}),
        (CQLConfig(), {}),
        (SACConfig(), {"proxy": "ensemble"}),
        (SACConfig(), {"proxy": "rnd_per_dynamics"}),
        (SACConfig().learners(learner_config_dict={FAST_KEY: False}), {}),
        (PPOConfig(), {}),
    ],
    ids=["SAC", "CQL", "SAC_ensemble", "SAC_rnd_per_dynamics", "SAC_opt_out", "PPO"],
)
def test_with_asor_keeps_rllibs_own_module_and_path(config, settings):
    """ASOR on a stock config stays on RLlib's path: no fast off-policy path, no module swap
    (tests/rllib/test_with_asor_arms.py compares the two arms in full)."""
    out = with_asor(config, **settings)
    assert out.learner_config_dict.get(FAST_KEY) is config.learner_config_dict.get(FAST_KEY)
    assert specs(out)[DEFAULT_MODULE_ID].module_class is None  # the config's default module


@pytest.mark.parametrize(
    "config, fast_module",
    [
        (fast_off_policy(SACConfig()), FastSACTorchRLModule),
        (fast_off_policy(CQLConfig()), FastCQLTorchRLModule),
    ],
    ids=["SAC", "CQL"],
)
def test_with_asor_keeps_the_fast_path_a_config_is_on(config, fast_module):
    out = with_asor(config)
    assert out.learner_config_dict[FAST_KEY] is True
    assert specs(out)[DEFAULT_MODULE_ID].module_class is fast_module


# ------------------------------------------------------------------ policies_to_train
def test_a_policies_to_train_list_is_kept_and_the_aux_modules_are_always_trained():
    config = two_policies(policies_to_train=["a"])
    out = with_asor(config)
    to_train = out.policies_to_train
    assert isinstance(to_train, _AlsoTrainAux) and to_train.user == ["a"]
    assert to_train("a") is True
    assert to_train("b") is False
    assert to_train(asor_module_id("a")) is True
    assert to_train(asor_module_id("b")) is True  # any ASOR module id
    assert config.policies_to_train == ["a"]


def test_a_policies_to_train_callable_gets_module_id_and_batch_and_aux_modules_bypass_it():
    calls = []

    def user(module_id, batch):
        calls.append((module_id, batch))
        return "yes" if module_id == "a" else ""

    to_train = with_asor(two_policies(policies_to_train=user)).policies_to_train
    assert to_train.user is user
    assert to_train("a", "batch") is True
    assert to_train("b", "other") is False
    assert to_train(asor_module_id("b"), "batch") is True
    assert calls == [("a", "batch"), ("b", "other")]


def test_policies_to_train_is_wrapped_only_once():
    user = ["a"]
    assert _AlsoTrainAux(_AlsoTrainAux(user)).user is user
    twice = with_asor(with_asor(two_policies(policies_to_train=["b"])))
    assert twice.policies_to_train.user == ["b"]
    assert twice.policies_to_train("b") is True and twice.policies_to_train("a") is False


def test_policies_to_train_stays_unset_when_the_user_left_it_unset():
    assert with_asor(two_policies()).policies_to_train is None
    assert with_asor(ppo()).policies_to_train is None


@pytest.mark.parametrize(
    "config, pids",
    [
        (ppo(), [DEFAULT_MODULE_ID]),
        (two_policies(), ["a", "b"]),
        (two_policies(policies_to_train=["b"]), ["b"]),
        (two_policies(policies_to_train=("b", "a")), ["a", "b"]),  # the policies' order
        (two_policies(policies_to_train=lambda mid, batch=None: mid == "a"), ["a", "b"]),
        (two_policies().multi_agent(policies_to_train=_AlsoTrainAux(["b"])), ["b"]),
    ],
    ids=["single_agent", "all", "list", "tuple", "callable", "wrapped_list"],
)
def test_trained_policy_ids(config, pids):
    assert trained_policy_ids(config) == pids


# ------------------------------------------------------------------ module specs
def test_single_agent_gets_one_learner_only_asor_module_with_the_settings():
    out = with_asor(ppo(), **SETTINGS)
    got = specs(out)
    assert list(got) == [DEFAULT_MODULE_ID, DISC]
    assert got[DEFAULT_MODULE_ID].module_class is None
    assert got[DISC].module_class is AsorModule
    assert got[DISC].learner_only is True
    assert got[DISC].model_config == {"asor": stored(**SETTINGS)}
    assert got[DISC].observation_space is None and got[DISC].action_space is None


def test_srpo_mode_wires_the_same_one_module():
    assert list(specs(with_asor(ppo(), mode="srpo"))) == [DEFAULT_MODULE_ID, DISC]


def test_multi_agent_aux_modules_belong_to_the_trained_policies_and_take_their_spaces():
    got = specs(with_asor(two_policies(policies_to_train=["b"])))
    assert set(got) == {"a", "b", asor_module_id("b")}
    for mid in (asor_module_id("b"),):
        assert got[mid].observation_space == OBS_B
        assert got[mid].action_space == ACT_B
        assert got[mid].learner_only is True


def test_multi_agent_without_policies_to_train_regularises_every_policy():
    got = specs(with_asor(two_policies(), mode="srpo"))
    assert set(got) == {"a", "b", asor_module_id("a"), asor_module_id("b")}
    assert got[asor_module_id("a")].observation_space == OBS
    assert got[asor_module_id("b")].action_space == ACT_B


def test_an_existing_single_module_spec_is_copied_to_every_policy_with_its_settings():
    user = RLModuleSpec(module_class=DefaultPPOTorchRLModule, model_config={"fcnet_hiddens": [7]})
    got = specs(with_asor(two_policies().rl_module(rl_module_spec=user)))
    for pid in ("a", "b"):
        assert got[pid].module_class is DefaultPPOTorchRLModule
        assert got[pid].model_config == {"fcnet_hiddens": [7]}
    # each policy has its own copy (a deep one: editing one leaves the others and the user's)
    got["a"].model_config["fcnet_hiddens"].append(1)
    assert got["b"].model_config == {"fcnet_hiddens": [7]}
    assert user.model_config == {"fcnet_hiddens": [7]}


def test_an_existing_multi_module_spec_keeps_its_policies_and_drops_stale_aux_modules():
    once = with_asor(two_policies().rl_module(model_config={"fcnet_hiddens": [5]}), mode="asor")
    specs(once)["a"].module_class = DefaultPPOTorchRLModule
    twice = with_asor(once, mode="srpo", seed=3)
    got = specs(twice)
    assert set(got) == {"a", "b", asor_module_id("a"), asor_module_id("b")}
    assert got["a"].module_class is DefaultPPOTorchRLModule
    assert got[asor_module_id("a")].model_config == {"asor": stored(mode="srpo", seed=3)}
    assert twice.learner_config_dict["asor"] == stored(mode="srpo", seed=3)


class _TeamModule(MultiRLModule):
    """A user's own MultiRLModule class."""


def test_a_users_multi_module_spec_keeps_its_class_and_settings():
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec

    user = MultiRLModuleSpec(
        multi_rl_module_class=_TeamModule,
        model_config={"shared": 1},
        rl_module_specs={"a": RLModuleSpec(), "b": RLModuleSpec()},
    )
    out = with_asor(two_policies().rl_module(rl_module_spec=user), mode="srpo")
    got = out._rl_module_spec
    assert got.multi_rl_module_class is _TeamModule and got.model_config == {"shared": 1}
    assert set(got.rl_module_specs) == {"a", "b", asor_module_id("a"), asor_module_id("b")}


def test_aux_modules_inherit_their_policys_spaces_when_built_and_keep_their_own():
    pid = "team.blue"  # a dotted policy id: the aux id is split at its first dot only
    asor = {"asor": stored(**SMALL)}
    spec = AsorMultiRLModuleSpec(
        rl_module_specs={
            pid: RLModuleSpec(
                module_class=DefaultPPOTorchRLModule,
                observation_space=OBS,
                action_space=ACT,
                model_config={"fcnet_hiddens": [8]},
            ),
            asor_module_id(pid): RLModuleSpec(
                module_class=AsorModule, learner_only=True, model_config=asor
            ),
            asor_module_id("other"): RLModuleSpec(  # spaces of its own: kept
                module_class=AsorModule,
                learner_only=True,
                observation_space=OBS_B,
                action_space=ACT_B,
                model_config=asor,
            ),
        }
    )
    disc = spec.build(asor_module_id(pid))  # one module, as asked
    assert isinstance(disc, AsorModule)
    assert (disc.observation_space, disc.action_space) == (OBS, ACT)
    multi = spec.build()
    assert isinstance(multi, MultiRLModule)
    assert (
        multi[asor_module_id(pid)].observation_space,
        multi[asor_module_id(pid)].action_space,
    ) == (OBS, ACT)
    own = multi[asor_module_id("other")]
    assert (own.observation_space, own.action_space) == (OBS_B, ACT_B)


# ------------------------------------------------------------------ Tune trainables
@pytest.fixture
def fresh_trainables(monkeypatch):
    """No trainable class cached yet (as in a new process): each test makes its own."""
    for name in [n for n in vars(trainable) if n.startswith("Asor") and n[4:] in SUPPORTED]:
        monkeypatch.delitem(vars(trainable), name)


def test_asor_trainable_is_a_named_cached_subclass_of_the_runs_algorithm(fresh_trainables):
    cls = asor_trainable("PPO")
    assert cls.__name__ == cls.__qualname__ == "AsorPPO"
    assert cls.__module__ == "rllib_asor.rllib.trainable"
    assert cls.__bases__ == (OverlappedPPO,)
    assert asor_trainable("PPO") is cls
    assert trainable.AsorPPO is cls
    sac = asor_trainable("SAC")
    assert sac.__name__ == "AsorSAC" and sac.__bases__ == (SAC,)
    assert asor_trainable("SAC") is sac


def test_asor_trainable_refuses_an_unsupported_run_naming_the_supported_ones():
    with pytest.raises(ValueError) as err:
        asor_trainable("DQN")
    assert str(err.value) == "ASOR does not support run='DQN': supported CQL, ESCP, MAPLE, PPO, SAC"


def test_the_trainables_constructor_applies_the_asor_block(monkeypatch, fresh_trainables):
    seen = []
    monkeypatch.setattr(OverlappedPPO, "__init__", lambda self, config=None: seen.append(config))
    cls = asor_trainable("PPO")
    cls({"asor": None, "lr": 0.5})
    cls({"asor": dict(SETTINGS), "lr": 0.5})
    assert seen[0] == {"lr": 0.5}
    assert isinstance(seen[1], PPOConfig) and seen[1].learner_class is AsorPPOTorchLearner
    assert seen[1].lr == 0.5


def test_module_getattr_recreates_a_trainable_class_by_name(fresh_trainables):
    cls = trainable.AsorCQL  # through the module's __getattr__ (as unpickling does)
    assert cls is asor_trainable("CQL")
    assert cls.__bases__ == (CQL,)
    assert getattr(trainable, "AsorSAC") is asor_trainable("SAC")  # noqa: B009


@pytest.mark.parametrize("name", ["AsorDQN", "BasePPO", "asorPPO", "Asor", "nothing"])
def test_module_getattr_refuses_other_names(name):
    with pytest.raises(AttributeError):
        getattr(trainable, name)


class Recorder:
    """A stand-in Algorithm: records what its constructor gets."""

    @classmethod
    def get_default_config(cls) -> PPOConfig:
        return PPOConfig()

    def __init__(self, config=None, *args, **kwargs):
        self.config, self.args, self.kwargs = config, args, kwargs


def recorded(*args, **kwargs) -> Recorder:
    """A Recorder built through `_asor_init` (made here, not at import, so that it is the
    `_asor_init` of the code under test)."""
    cls = type("Recorded", (Recorder,), {"__init__": _asor_init(Recorder)})
    return cls(*args, **kwargs)


def test_a_config_dict_with_an_asor_block_becomes_a_wired_algorithm_config():
    given = {"asor": dict(SETTINGS), "lr": 0.25, "gamma": 0.9}
    before = {"asor": dict(SETTINGS), "lr": 0.25, "gamma": 0.9}
    made = recorded(given, "positional", flag=True)
    assert isinstance(made.config, PPOConfig)
    assert made.config.lr == 0.25 and made.config.gamma == 0.9
    assert made.config.learner_class is AsorPPOTorchLearner
    assert made.config.learner_config_dict == {"asor": stored(**SETTINGS)}
    assert made.args == ("positional",) and made.kwargs == {"flag": True}
    assert given == before  # the caller's dict (Tune's) is not modified


def test_an_asor_block_of_none_gives_the_plain_config_dict():
    given = {"asor": None, "lr": 0.25}
    made = recorded(given)
    assert made.config == {"lr": 0.25} and type(made.config) is dict
    assert given == {"asor": None, "lr": 0.25}


@pytest.mark.parametrize(
    "config", [{"lr": 0.25}, None, PPOConfig()], ids=["dict", "none", "config"]
)
def test_a_config_without_an_asor_block_passes_through_unchanged(config):
    made = recorded(config, "positional", flag=True)
    assert made.config is config
    assert made.args == ("positional",) and made.kwargs == {"flag": True}


# ------------------------------------------------------------------ metrics callback
def test_lift_asor_metrics_gives_a_flat_dict_of_floats_for_one_policy():
    result = {
        "learners": {
            DISC: {
                "disc_loss": np.float32(0.5),
                "disc_acc_real": 0.75,
                "disc_acc_fake": 0.25,
                "lambda": 1,
                "rnd_loss": np.float64(0.125),
                "num_module_steps_trained": 60,  # not an ASOR metric
            },
            DEFAULT_MODULE_ID: {"disc_loss": 9.0, "policy_loss": 1.0},
            asor_module_id("not_a_dict"): 3.0,
        }
    }
    lifted = lift_asor_metrics(result)
    assert lifted == {
        "disc_loss": 0.5,
        "disc_acc_real": 0.75,
        "disc_acc_fake": 0.25,
        "disc_acc": 0.5,
        "lambda": 1.0,
        "rnd_loss": 0.125,
    }
    assert all(type(v) is float for v in lifted.values())


def test_lift_asor_metrics_keys_several_policies_by_policy_id():
    result = {
        "learners": {
            asor_module_id("a"): {"disc_acc_real": 0.5, "disc_acc_fake": 0.75},
            asor_module_id("b"): {"disc_acc_real": 1.0, "ensemble_loss": 2.0},  # no disc_acc
        }
    }
    assert lift_asor_metrics(result) == {
        "a": {"disc_acc_real": 0.5, "disc_acc_fake": 0.75, "disc_acc": 0.625},
        "b": {"disc_acc_real": 1.0, "ensemble_loss": 2.0},
    }


@pytest.mark.parametrize(
    "result",
    [{}, {"learners": None}, {"learners": {DEFAULT_MODULE_ID: {"disc_loss": 1.0}}}],
    ids=["no_learners", "learners_none", "no_aux_modules"],
)
def test_lift_asor_metrics_is_empty_without_asor_modules(result):
    assert lift_asor_metrics(result) == {}


def test_the_callback_adds_asor_to_the_result_only_when_there_is_something_to_lift():
    callback = AsorMetricsCallback()
    result = {"learners": {DISC: {"disc_loss": 0.5, "policy_loss": 1.0}}}
    callback.on_train_result(algorithm=None, result=result)
    assert result["asor"] == {"disc_loss": 0.5}
    plain = {"learners": {DEFAULT_MODULE_ID: {"policy_loss": 1.0}}}
    callback.on_train_result(algorithm=None, result=plain)
    assert plain == {"learners": {DEFAULT_MODULE_ID: {"policy_loss": 1.0}}}


# ------------------------------------------------------------------ the slow-SAC note
# `with_asor(SACConfig())` wraps RLlib's own SAC Learner (~1.8 env steps/s against
# FastSACConfig's ~12 on Hopper, docs/results.md): it says so once, pointing at
# `rllib_asor.FastSACConfig`; configs that chose a path (the fast one, or RLlib's on purpose, as
# `rllib train` records for `run: SAC`) and ASOR settings the fast path cannot run get no note.
def _slow_sac_notes(config, **settings) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with_asor(config.environment("Pendulum-v1"), **settings)
    return [str(w.message) for w in caught if "FastSACConfig" in str(w.message)]


def test_rllibs_own_sac_gets_one_line_pointing_at_fast_sac():
    [note] = _slow_sac_notes(SACConfig())
    assert "rllib_asor.FastSACConfig" in note and "RLlib's own SAC Learner" in note
    assert "\n" not in note


@pytest.mark.parametrize(
    "config",
    [
        FastSACConfig(),
        SACConfig().learners(learner_config_dict={FAST_KEY: False}),  # RLlib's SAC, on purpose
    ],
    ids=["fast", "opted-out"],
)
def test_a_config_that_chose_its_path_gets_no_note(config):
    assert _slow_sac_notes(config) == []


def test_per_dynamics_rnd_which_the_fast_path_cannot_run_gets_no_note():
    assert _slow_sac_notes(SACConfig(), proxy="rnd_per_dynamics") == []


def test_the_cli_run_sac_path_gets_no_note(tmp_path):
    path = tmp_path / "sac.yaml"
    path.write_text("x:\n  env: Pendulum-v1\n  run: SAC\n  stop: {training_iteration: 1}\n")
    [exp] = experiment.load_file(str(path))
    cfg = experiment.build_algo_config(exp)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with_asor(cfg)
    assert not [w for w in caught if "FastSACConfig" in str(w.message)]
