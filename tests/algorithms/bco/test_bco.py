"""BCO: behavioural cloning's loss on hand-made tensors, BCO(α) on the lava world (random steps
first, α·pre_demo_steps later, the model relabels the experts, checkpoint round trip), BCO(0),
two Learners, offline on a `rllib data collect` dataset, bad settings in one line."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from ray.rllib.core.columns import Columns

from rllib_asor.algorithms.bco.config import STATE_KEY, BcoConfig
from rllib_asor.algorithms.bco.settings import BcoSettings
from tests.algorithms.lava_expert import lava_demonstrations_file

LAVA = "rllib_asor/LavaWorld-v0"


@pytest.fixture(scope="module")
def demos_path(tmp_path_factory):
    return lava_demonstrations_file(tmp_path_factory.mktemp("bco") / "lava.npz", episodes=10)


def bco_config(demos_path, **bco) -> BcoConfig:
    settings = {"alpha": 0.5, "pre_demo_steps": 200, "idm_steps": 50, "bc_epochs": 2, **bco}
    return (
        BcoConfig()
        .environment(LAVA)
        .rl_module(model_config={"fcnet_hiddens": [16]})
        .bco(demonstrations=str(demos_path), **settings)
        .debugging(seed=0)
    )


def test_bc_loss_is_minus_the_mean_log_likelihood_of_the_inferred_actions(ray_session, demos_path):
    algo = bco_config(demos_path).build_algo()
    try:
        learner = algo.learner_group._learner
        module = learner.module["default_policy"]
        obs = torch.eye(15)[:2]  # two hand-made observations
        batch = {Columns.OBS: obs, Columns.ACTIONS: torch.tensor([1, 3])}
        fwd = module.forward_train(batch)
        loss = learner.compute_loss_for_module(
            module_id="default_policy", config=None, batch=batch, fwd_out=fwd
        )
        logp = torch.log_softmax(fwd[Columns.ACTION_DIST_INPUTS], -1)
        expected = -(logp[0, 1] + logp[1, 3]) / 2
        assert loss.item() == pytest.approx(expected.item(), rel=1e-6)
    finally:
        algo.stop()


def test_bco_alpha_samples_random_steps_then_alpha_times_as_many_and_restores(
    ray_session, demos_path
):
    from ray.rllib.algorithms.algorithm import Algorithm

    algo = bco_config(demos_path, pre_demo_steps=400, alpha=0.25).build_algo()
    try:
        first = algo.train()
        assert first["bco"]["new_transitions"] >= 400  # the random pre-demonstration steps
        assert first["bco"]["demo_transitions"] == len(algo._demos)
        second = algo.train()
        # at least α·400 = 100 (the env runner samples in whole fragments)
        assert 100 <= second["bco"]["new_transitions"] < first["bco"]["new_transitions"]
        assert len(algo.idm) == first["bco"]["new_transitions"] + second["bco"]["new_transitions"]
        assert math.isfinite(second["learners"]["default_policy"]["bc_loss"])
        labels = algo._labels.copy()
        assert labels.shape == (len(algo._demos),) and set(labels) <= {0, 1, 2, 3}
        weights = {k: v.clone() for k, v in algo.idm.model.state_dict().items()}
        path = algo.save_to_path()
    finally:
        algo.stop()
    restored = Algorithm.from_checkpoint(path)
    try:
        assert len(restored.idm) == len(algo.idm)
        assert np.array_equal(restored._labels, labels)
        state = restored.idm.model.state_dict()
        assert all(torch.equal(state[k], v) for k, v in weights.items())
        assert STATE_KEY in restored.get_state()
        assert restored.train()["bco"]["new_transitions"] > 0
    finally:
        restored.stop()


def test_bco_zero_interacts_only_before_the_first_cloning(ray_session, demos_path):
    algo = bco_config(demos_path, alpha=0.0).build_algo()
    try:
        algo.train()
        rows = len(algo.idm)
        assert algo.train()["bco"]["new_transitions"] == 0 and len(algo.idm) == rows
    finally:
        algo.stop()


@pytest.mark.slow  # 30 s: two Learner actors on 2 cores
def test_bco_clones_on_two_learners_with_one_policy(ray_session, demos_path):
    config = bco_config(demos_path).learners(num_learners=2, num_cpus_per_learner=0.5)
    algo = config.build_algo()
    try:
        for _ in range(2):
            result = algo.train()
        assert math.isfinite(result["learners"]["default_policy"]["bc_loss"])
        calls = algo.learner_group.foreach_learner(
            lambda lr: {
                k: v.cpu().numpy() for k, v in lr.module["default_policy"].state_dict().items()
            }
        )
        a, b = [c.get() for c in calls]
        assert all(np.array_equal(a[k], b[k]) for k in a), "the ranks' policies differ"
    finally:
        algo.stop()


def test_offline_bco_learns_its_model_from_the_data_and_evaluates_itself(
    ray_session, hopper_offline_data
):
    from rllib_asor.algorithms.maple.data import read_part

    parts = [str(hopper_offline_data / d / "random") for d in ("original", "body_mass")]
    config = (
        BcoConfig()
        .environment("rllib_asor/HopperShift-v0")
        .offline_data(input_=parts)
        .bco(demonstrations=str(hopper_offline_data), idm_steps=20, bc_epochs=1,
             evaluation_interval=1, evaluation_episodes=1)
    )  # fmt: skip
    algo = config.build_algo()
    try:
        result = algo.train()
        steps = sum(len(a) for p in parts for _, a, _, _ in read_part(p))
        assert result["bco"]["new_transitions"] == steps == len(algo.idm)
        assert math.isfinite(result["evaluation"]["mean/return_mean"])
        dynamics = {key.split("/")[0] for key in result["evaluation"]}
        assert dynamics >= {"original", "body_mass", "density_10", "mean"}
        assert algo.train()["bco"]["new_transitions"] == 0  # the data is read once
        acts = algo._labels
        assert acts.shape == (len(algo._demos), 3) and np.abs(acts).max() <= 1.0
    finally:
        algo.stop()


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_bco_clones_with_its_learner_on_the_gpu(ray_session, demos_path):
    algo = bco_config(demos_path).learners(num_gpus_per_learner=1).build_algo()
    try:
        for _ in range(2):
            result = algo.train()
        assert math.isfinite(result["learners"]["default_policy"]["bc_loss"])
        module = algo.learner_group._learner.module["default_policy"]
        assert all(p.device.type == "cuda" for p in module.parameters())
    finally:
        algo.stop()


@pytest.mark.parametrize(
    ("settings", "match"),
    [
        ({"alpha": -1}, r"bco\.alpha=-1 is not allowed; expected a number ≥ 0"),
        ({"pre_demo_steps": 0}, r"bco\.pre_demo_steps=0 is not allowed; expected an int ≥ 1"),
        ({"idm_lr": 0}, r"bco\.idm_lr=0 is not allowed; expected a number > 0"),
        ({"alfa": 0.1}, r"alfa"),
    ],
)
def test_bad_settings_name_the_key_the_value_and_what_is_allowed(settings, match):
    with pytest.raises(ValueError, match=match) as e:
        BcoConfig().bco(**settings)
    assert "\n" not in str(e.value)
    assert BcoSettings().alpha == 0.0


def test_missing_or_mismatched_demonstrations_fail_in_one_line(demos_path):
    with pytest.raises(ValueError, match="BCO needs expert demonstrations"):
        BcoConfig().environment(LAVA).validate()
    with pytest.raises(ValueError, match=r"expected \(3,\), got \(15,\)"):
        BcoConfig().environment(LAVA, env_config={"obs_mode": "raw"}).bco(
            demonstrations=str(demos_path)
        ).validate()
