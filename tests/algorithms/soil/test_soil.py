"""SOIL: the inverse dynamics model's and the demonstration term's losses on hand-made tensors,
the transitions its piece reads from PPO's batch, SOIL on the lava world from Python (with and
without ASOR, checkpoint round trip, two Learners), offline on MARWIL, bad settings in one line.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
import torch
from ray.rllib.core.columns import Columns

import rllib_asor
from rllib_asor.algorithms.common.demonstrations import Demonstrations
from rllib_asor.algorithms.common.inverse_dynamics import (
    IdmTrainer,
    InverseDynamicsModel,
    idm_loss,
    imitation_loss,
)
from rllib_asor.algorithms.soil.config import SoilConfig, SoilOfflineConfig
from rllib_asor.algorithms.soil.connector import valid_transitions
from rllib_asor.algorithms.soil.imitation import SoilImitation
from rllib_asor.algorithms.soil.learner import STATE_KEY, SoilLearnerMixin
from rllib_asor.algorithms.soil.settings import SoilSettings
from tests.algorithms.lava_expert import lava_demonstrations_file

LAVA = "rllib_asor/LavaWorld-v0"


# ----------------------------------------------------------------------------- by hand
def test_idm_loss_is_cross_entropy_for_discrete_and_squared_error_for_box_actions():
    logits = torch.tensor([[0.0, 0.0], [math.log(3.0), 0.0]])
    # row 0: p(a=1) = 1/2; row 1: p(a=0) = 3/4
    expected = (math.log(2.0) - math.log(0.75)) / 2
    assert idm_loss(logits, torch.tensor([1, 0]), discrete=True).item() == pytest.approx(expected)
    pred = torch.tensor([[1.0, 2.0], [0.0, 0.0]])
    act = torch.tensor([[0.0, 0.0], [0.0, 3.0]])
    assert idm_loss(pred, act, discrete=False).item() == pytest.approx((1 + 4 + 0 + 9) / 4)


def test_imitation_loss_is_the_weighted_negative_mean_log_likelihood():
    assert imitation_loss(torch.tensor([-1.0, -3.0]), 0.5).item() == pytest.approx(1.0)


def test_inferred_actions_are_the_argmax_or_the_mean_clipped_to_the_box():
    model = InverseDynamicsModel(1, gym.spaces.Box(-1.0, 1.0, (1,), np.float32), hiddens=(4,))
    with torch.no_grad():
        last = model.net[-1]
        last.weight.zero_()
        last.bias.fill_(5.0)  # mean action 5, outside the box
    assert model.infer(torch.zeros(2, 1), torch.zeros(2, 1)).tolist() == [[1.0], [1.0]]
    model = InverseDynamicsModel(1, gym.spaces.Discrete(3), hiddens=(4,))
    with torch.no_grad():
        model.net[-1].weight.zero_()
        model.net[-1].bias.copy_(torch.tensor([0.0, 2.0, 1.0]))
    assert model.infer(torch.zeros(2, 1), torch.zeros(2, 1)).tolist() == [1, 1]


def test_demonstration_weight_is_lambda0_lambda1_to_the_k_times_demo_over_batch_rows():
    demos = Demonstrations.of(np.zeros((4, 2)), np.ones((4, 2)), [0] * 4, [False] * 4)
    settings = SoilSettings(demonstrations="x", demo_weight=0.1, demo_decay=0.5)
    soil = SoilImitation(settings, demos, gym.spaces.Discrete(2), batch_size=8)
    assert soil.weight() == pytest.approx(0.1 * 4 / 8)
    soil.iteration = 2
    assert soil.weight() == pytest.approx(0.1 * 0.25 * 4 / 8)


def test_demonstration_term_is_minus_w_log_pi_of_the_inferred_action():
    from ray.rllib.algorithms.ppo.torch.default_ppo_torch_rl_module import (
        DefaultPPOTorchRLModule,
    )
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    module = RLModuleSpec(
        module_class=DefaultPPOTorchRLModule,
        observation_space=space,
        action_space=gym.spaces.Discrete(3),
        model_config={"fcnet_hiddens": [8]},
    ).build()
    obs = np.tile(np.array([[0.3, -0.2]], np.float32), (5, 1))  # every row alike
    demos = Demonstrations.of(obs, obs, [0] * 5, [False] * 5)
    soil = SoilImitation(SoilSettings(demonstrations="x"), demos, gym.spaces.Discrete(3), 10)
    soil.labels = torch.full((5,), 2)
    loss, stats = soil.loss(module, n=3)
    logits = module.forward_train({Columns.OBS: torch.as_tensor(obs[:1])})[
        Columns.ACTION_DIST_INPUTS
    ]
    logp = torch.log_softmax(logits, -1)[0, 2]
    w = 0.1 * 5 / 10
    assert loss.item() == pytest.approx(-w * logp.item(), rel=1e-5)
    assert stats["demo_w"] == pytest.approx(w)


def test_valid_transitions_pair_each_valid_row_with_the_next_row_of_its_episode():
    # two episode chunks: 0,1,2 then bootstrap 9; 10,11 then bootstrap 19
    obs = torch.tensor([0.0, 1, 2, 9, 10, 11, 19]).unsqueeze(-1)
    mask = torch.tensor([1, 1, 1, 0, 1, 1, 0], dtype=torch.bool)
    batch = {Columns.OBS: obs, Columns.ACTIONS: torch.arange(7), Columns.LOSS_MASK: mask}
    s, a, s2 = valid_transitions(batch)
    assert s.squeeze(-1).tolist() == [0, 1, 2, 10, 11]
    assert s2.squeeze(-1).tolist() == [1, 2, 9, 11, 19]
    assert a.tolist() == [0, 1, 2, 4, 5]


def test_idm_trainer_learns_a_known_inverse_model_and_its_state_round_trips():
    rng = np.random.default_rng(0)
    s = rng.normal(size=(512, 2)).astype(np.float32)
    a = rng.integers(0, 4, 512)
    moves = np.array([[1, 0], [0, 1], [-1, 0], [0, -1]], np.float32)
    idm = IdmTrainer(2, gym.spaces.Discrete(4), lr=3e-3, steps=400, batch_size=64, seed=0)
    idm.add(s, a, s + moves[a])
    stats = idm.update()
    assert (idm.infer(s, s + moves[a]).cpu().numpy() == a).mean() > 0.95, stats
    other = IdmTrainer(2, gym.spaces.Discrete(4), seed=1)
    other.set_state(idm.get_state())
    assert torch.equal(other.infer(s, s + moves[a]), idm.infer(s, s + moves[a]))
    assert len(other) == 512


# ----------------------------------------------------------------------------- on RLlib
@pytest.fixture(scope="module")
def demos_path(tmp_path_factory):
    return lava_demonstrations_file(tmp_path_factory.mktemp("soil") / "lava.npz", episodes=10)


def soil_config(demos_path, **soil) -> SoilConfig:
    return (
        SoilConfig()
        .environment(LAVA)
        .env_runners(num_env_runners=0)
        .training(train_batch_size_per_learner=128, minibatch_size=64, num_epochs=2)
        .rl_module(model_config={"fcnet_hiddens": [16]})
        .soil(demonstrations=str(demos_path), idm_steps=10, **soil)
        .debugging(seed=0)
    )


def test_soil_trains_on_lava_and_restores_its_inverse_dynamics_model(ray_session, demos_path):
    from ray.rllib.algorithms.algorithm import Algorithm

    algo = soil_config(demos_path).build_algo()
    try:
        learner = algo.learner_group._learner
        assert isinstance(learner, SoilLearnerMixin)
        first = algo.train()["learners"]["soil"]
        second = algo.train()["learners"]["soil"]
        assert second["idm_rows"] == 2 * first["idm_rows"] > 0  # each batch's valid rows
        assert math.isfinite(second["idm_loss"]) and second["demo_logp"] < 0
        assert second["demo_w"] == pytest.approx(first["demo_w"] * 0.99)  # λ1 per iteration
        assert learner.soil.iteration == 2
        weights = {k: v.clone() for k, v in learner.soil.idm.model.state_dict().items()}
        path = algo.save_to_path()
    finally:
        algo.stop()
    restored = Algorithm.from_checkpoint(path)
    try:
        soil = restored.learner_group._learner.soil
        assert soil.iteration == 2 and len(soil.idm) == second["idm_rows"]
        state = soil.idm.model.state_dict()
        assert all(torch.equal(state[k], v) for k, v in weights.items())
        assert restored.train()["learners"]["soil"]["idm_rows"] > second["idm_rows"]
    finally:
        restored.stop()


def test_soil_with_asor_keeps_soils_term_and_adds_asors_bonus(ray_session, demos_path):
    from rllib_asor.rllib.learners import AsorPPOTorchLearner

    algo = rllib_asor.with_asor(soil_config(demos_path), seed=0).build_algo()
    try:
        learner = algo.learner_group._learner
        assert isinstance(learner, SoilLearnerMixin) and isinstance(learner, AsorPPOTorchLearner)
        result = algo.train()
        assert math.isfinite(result["learners"]["soil"]["demo_loss"])
        assert "asor" in result and STATE_KEY in learner.get_state()
    finally:
        algo.stop()


@pytest.mark.slow  # 30 s: two Learner actors on 2 cores
def test_soil_trains_on_two_learners_with_one_inverse_dynamics_model(ray_session, demos_path):
    config = soil_config(demos_path).learners(num_learners=2, num_cpus_per_learner=0.5)
    algo = config.build_algo()
    try:
        for _ in range(2):
            result = algo.train()
        assert math.isfinite(result["learners"]["soil"]["idm_loss"])
        calls = algo.learner_group.foreach_learner(
            lambda lr: {k: v.cpu().numpy() for k, v in lr.soil.idm.model.state_dict().items()}
        )
        a, b = [c.get() for c in calls]
        assert all(np.array_equal(a[k], b[k]) for k in a), "the ranks' models differ"
    finally:
        algo.stop()


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
@pytest.mark.parametrize("asor", [False, True], ids=["soil", "soil-asor"])
def test_soil_trains_with_its_learner_on_the_gpu(ray_session, demos_path, asor):
    config = soil_config(demos_path).learners(num_gpus_per_learner=1)
    algo = (rllib_asor.with_asor(config, seed=0) if asor else config).build_algo()
    try:
        for _ in range(2):
            result = algo.train()
        assert math.isfinite(result["learners"]["soil"]["demo_loss"])
        learner = algo.learner_group._learner
        assert all(p.device.type == "cuda" for p in learner.soil.idm.model.parameters())
        assert learner.soil.obs.device.type == "cuda"
    finally:
        algo.stop()


@pytest.mark.slow  # MARWIL's Ray Data reader starts its own actors: ~50 s
def test_offline_soil_fits_the_model_on_the_data_and_trains_marwil(
    ray_session, hopper_offline_data
):
    from rllib_asor.algorithms.maple.data import read_part

    parts = [str(hopper_offline_data / d / "random") for d in ("original", "body_mass")]
    config = (
        SoilOfflineConfig()
        .environment("rllib_asor/HopperShift-v0")
        .offline_data(input_=parts, input_read_episodes=True, dataset_num_iters_per_learner=2)
        .training(train_batch_size_per_learner=64)
        .env_runners(num_env_runners=0)
        .soil(demonstrations=str(hopper_offline_data), idm_steps=20, evaluation_interval=1,
              evaluation_episodes=1)
    )  # fmt: skip
    algo = config.build_algo()
    try:
        soil = algo.learner_group._learner.soil
        steps = sum(len(a) for p in parts for _, a, _, _ in read_part(p))
        assert len(soil.idm) == steps and soil.labels is not None  # the data's own transitions
        result = algo.train()
        assert math.isfinite(result["learners"]["soil"]["demo_loss"])
        assert math.isfinite(result["evaluation"]["mean/return_mean"])
    finally:
        algo.stop()


@pytest.mark.parametrize(
    ("settings", "match"),
    [
        (
            {"demo_decay": 1.5},
            r"soil\.demo_decay=1\.5 is not allowed; expected a number in \[0, 1\]",
        ),
        ({"idm_steps": 0}, r"soil\.idm_steps=0 is not allowed; expected an int ≥ 1"),
        ({"idm_hiddens": []}, r"soil\.idm_hiddens=\[\] is not allowed"),
        ({"lambda0": 1}, r"lambda0"),
    ],
)
def test_bad_settings_name_the_key_the_value_and_what_is_allowed(settings, match):
    with pytest.raises(ValueError, match=match) as e:
        SoilConfig().soil(**settings)
    assert "\n" not in str(e.value)


def test_missing_or_mismatched_demonstrations_fail_in_one_line(tmp_path, demos_path):
    with pytest.raises(ValueError, match="SOIL needs expert demonstrations"):
        SoilConfig().environment(LAVA).validate()
    with pytest.raises(ValueError, match=r"expected \(3,\), got \(15,\)"):
        SoilConfig().environment(LAVA, env_config={"obs_mode": "raw"}).soil(
            demonstrations=str(demos_path)
        ).validate()
    with pytest.raises(ValueError, match="use SoilOfflineConfig"):
        soil_config(demos_path).offline_data(input_=[str(tmp_path)]).validate()
