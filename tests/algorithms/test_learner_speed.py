"""Our Learners' same-math speed-ups and PPO's opt-in row drop, through real RLlib."""

import copy

import numpy as np
import pytest
import torch
import tree
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.connectors.learner import GeneralAdvantageEstimation
from ray.rllib.core import DEFAULT_MODULE_ID, Columns
from ray.rllib.evaluation.postprocessing import Postprocessing
from ray.rllib.policy.sample_batch import SampleBatch
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

import rllib_asor
import rllib_asor.envs  # noqa: F401  (registers rllib_asor/LavaWorld-v0)
from rllib_asor.algorithms.common.learner_speed import IndexSelectShuffleBatch, fuse_adam
from rllib_asor.algorithms.ppo.lean import DropMaskedRows, LeanPPOTorchLearner, drop_bootstrap_rows
from rllib_asor.rllib.connector import SHARED_VALUES, AsorRewardConnector, SharedValuesGAE
from tests.rllib.test_ppo_asor import lava_ppo_config

DISC = "asor_disc.default_policy"


def piece_names(algo) -> list[str]:
    return [type(c).__name__ for c in algo.learner_group._learner._learner_connector.connectors]


def test_fuse_adam_switches_a_fresh_adam_and_steps_as_torchs_default_adam():
    torch.manual_seed(0)
    params = [torch.nn.Parameter(torch.randn(5, 3)), torch.nn.Parameter(torch.randn(3))]
    twins = [torch.nn.Parameter(p.detach().clone()) for p in params]
    fused, plain = torch.optim.Adam(params, lr=1e-2), torch.optim.Adam(twins, lr=1e-2)
    assert fuse_adam(fused) and all(g["fused"] for g in fused.param_groups)
    for _ in range(3):
        for ps, opt in ((params, fused), (twins, plain)):
            opt.zero_grad()
            sum((p**3).sum() for p in ps).backward()
            opt.step()
    for a, b in zip(params, twins, strict=True):
        torch.testing.assert_close(a, b)


def test_fuse_adam_leaves_other_optimizers_explicit_choices_and_stepped_ones():
    p = [torch.nn.Parameter(torch.randn(3))]
    assert not fuse_adam(torch.optim.SGD(p, lr=0.1))
    assert not fuse_adam(torch.optim.Adam(p, foreach=True))
    assert not fuse_adam(torch.optim.Adam(p, fused=False))
    stepped = torch.optim.Adam(p)
    p[0].grad = torch.ones(3)
    stepped.step()
    assert not fuse_adam(stepped)


def test_index_select_shuffle_puts_the_rows_in_rllibs_order():
    data = {
        "obs": {"grid": torch.randn(50, 2, 3, 3), "pos": np.arange(50.0)},
        "actions": torch.arange(50),
    }
    ours = IndexSelectShuffleBatch(copy.deepcopy(data))
    theirs = SampleBatch(copy.deepcopy(data))
    np.random.seed(3)
    ours.shuffle()
    np.random.seed(3)
    theirs.shuffle()
    tree.map_structure(np.testing.assert_array_equal, dict(ours), dict(theirs))
    assert not torch.equal(ours["actions"], data["actions"])  # it did shuffle


def test_drop_masked_rows_keeps_valid_rows_and_removes_the_mask():
    mask = torch.tensor([True, True, False, True, False])
    batch = {
        "p": {
            Columns.LOSS_MASK: mask,
            "x": torch.arange(5),
            "o": {"g": torch.arange(10).view(5, 2)},
        }
    }

    class Module:
        def is_stateful(self):
            return False

    out = DropMaskedRows()(rl_module={"p": Module()}, batch=batch, episodes=[])
    assert Columns.LOSS_MASK not in out["p"]
    assert out["p"]["x"].tolist() == [0, 1, 3]
    assert out["p"]["o"]["g"].tolist() == [[0, 1], [2, 3], [6, 7]]


def test_drop_bootstrap_rows_needs_ppo_and_a_learner_that_reads_it():
    from ray.rllib.algorithms.ppo.torch.ppo_torch_learner import PPOTorchLearner

    with pytest.raises(ValueError, match="needs a PPO config, got SAC"):
        drop_bootstrap_rows(SACConfig())
    with pytest.raises(ValueError, match="PPOTorchLearner would ignore it; mix .*LeanPPOMixin"):
        drop_bootstrap_rows(lava_ppo_config().learners(learner_class=PPOTorchLearner))


@pytest.mark.parametrize("order", ["drop_then_asor", "asor_then_drop", "no_asor"])
def test_drop_bootstrap_rows_trains_each_valid_row_num_epochs_times(ray_session, order):
    config = lava_ppo_config()
    if order == "drop_then_asor":
        config = rllib_asor.with_asor(drop_bootstrap_rows(config), seed=0)
    elif order == "asor_then_drop":
        config = drop_bootstrap_rows(rllib_asor.with_asor(config, seed=0))
    else:
        config = drop_bootstrap_rows(config)
        assert config.learner_class is LeanPPOTorchLearner
    algo = config.build_algo()
    try:
        names = piece_names(algo)
        assert names[-1] == "DropMaskedRows"
        if order != "no_asor":
            assert names[-3:-1] == ["AsorRewardConnector", "SharedValuesGAE"]
        for _ in range(2):
            result = algo.train()
        policy = result["learners"][DEFAULT_MODULE_ID]
        sampled = result["env_runners"]["num_env_steps_sampled"]
        assert policy["num_module_steps_trained"] == 2 * sampled  # num_epochs × valid rows
        assert "diff_num_grad_updates_vs_sampler_policy" in policy
    finally:
        algo.stop()


def test_without_the_drop_ppo_still_trains_the_masked_rows(ray_session):
    algo = rllib_asor.with_asor(lava_ppo_config(), seed=0).build_algo()
    try:
        assert "DropMaskedRows" not in piece_names(algo)
        result = algo.train()
        policy_rows = result["learners"][DEFAULT_MODULE_ID]["num_module_steps_trained"]
        assert policy_rows > 2 * result["env_runners"]["num_env_steps_sampled"]
        # ASOR's module trains outside RLlib's minibatch loop: RLlib trains no rows of it
        assert "num_module_steps_trained" not in result["learners"].get(DISC, {})
    finally:
        algo.stop()


def test_gae_takes_asors_critic_values_and_computes_what_rllibs_gae_does(ray_session):
    algo = rllib_asor.with_asor(lava_ppo_config(), seed=0).build_algo()
    try:
        learner = algo.learner_group._learner
        pieces = learner._learner_connector.connectors
        assert not any(type(c) is GeneralAdvantageEstimation for c in pieces)
        at = next(i for i, c in enumerate(pieces) if isinstance(c, SharedValuesGAE))
        assert isinstance(pieces[at - 1], AsorRewardConnector)
        episodes = copy.deepcopy(algo.env_runner.sample(num_timesteps=200, random_actions=False))
        batch, shared = {}, {}
        with torch.no_grad():
            for piece in pieces[:at]:
                batch = piece(
                    rl_module=learner.module,
                    batch=batch,
                    episodes=episodes,
                    shared_data=shared,
                    metrics=learner.metrics,
                )
            assert DEFAULT_MODULE_ID in shared[SHARED_VALUES]
            twin = copy.deepcopy(batch)
            module = learner.module[DEFAULT_MODULE_ID].unwrapped()
            calls = []
            original = type(module).compute_values
            type(module).compute_values = lambda self, *a, **k: (
                calls.append(1) or original(self, *a, **k)
            )
            try:
                ours = pieces[at](
                    rl_module=learner.module, batch=batch, episodes=episodes, shared_data=shared
                )
                assert calls == []  # no second critic pass
                stock = GeneralAdvantageEstimation(
                    gamma=pieces[at].gamma, lambda_=pieces[at].lambda_
                )
                theirs = stock(
                    rl_module=learner.module, batch=twin, episodes=episodes, shared_data={}
                )
                assert calls == [1]
            finally:
                type(module).compute_values = original
        assert "compute_values" not in vars(module)  # the shared values are gone again
        for column in (Postprocessing.ADVANTAGES, Postprocessing.VALUE_TARGETS):
            torch.testing.assert_close(
                ours[DEFAULT_MODULE_ID][column], theirs[DEFAULT_MODULE_ID][column], rtol=0, atol=0
            )
    finally:
        algo.stop()


@pytest.mark.timeout(120)
def test_an_update_without_minibatch_size_ends_after_the_policys_epochs(ray_session):
    """Without a minibatch size RLlib's iterator runs until every module it tracks covered
    num_epochs; ASOR's module is not in the batch and must not keep it running."""
    algo = rllib_asor.with_asor(lava_ppo_config(), seed=0).build_algo()
    try:
        learner = algo.learner_group._learner
        episodes = copy.deepcopy(algo.env_runner.sample(num_timesteps=128, random_actions=False))
        optimizer = learner.get_optimizer(module_id=DEFAULT_MODULE_ID)
        learner.update(
            episodes=episodes, timesteps={NUM_ENV_STEPS_SAMPLED_LIFETIME: 1000}, num_epochs=3
        )
        steps = max(int(s["step"]) for s in optimizer.state.values())
        assert 3 <= steps <= 4
    finally:
        algo.stop()
