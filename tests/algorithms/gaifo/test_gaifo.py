"""GAIfO: its reward and loss on hand-made tensors, the reward piece on a hand-made PPO batch,
GAIfO on the lava world (alone, with ASOR, checkpoint round trip, two Learners, a GPU) and bad
input in one line."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from ray.rllib.core.columns import Columns

import rllib_asor
from rllib_asor.algorithms.common.demonstrations import Demonstrations, save_demonstrations
from rllib_asor.algorithms.gaifo.config import GaifoConfig
from rllib_asor.algorithms.gaifo.connector import GaifoRewardPiece
from rllib_asor.algorithms.gaifo.reward import gaifo_loss, imitation_reward, transition_features
from rllib_asor.algorithms.gaifo.settings import GaifoSettings
from rllib_asor.algorithms.gaifo.trainer import GaifoTrainer

pytestmark = pytest.mark.heavy  # starts Ray or a subprocess: scheduled first (conftest)

LAVA = "rllib_asor/LavaWorld-v0"


def _demos(dim: int = 2, n: int = 8) -> Demonstrations:
    obs = np.arange(n * dim, dtype=np.float32).reshape(n, dim)
    return Demonstrations.of(obs, obs + 1, np.zeros(n), np.zeros(n, bool))


@pytest.fixture(scope="module")
def lava_demos(tmp_path_factory) -> str:
    """State-only demonstrations of the lava world's best memoryless policy (8 episodes)."""
    from rllib_asor.algorithms.common.demonstrations import rollout_demonstrations
    from rllib_asor.envs.lava import reactive_expert

    demos = rollout_demonstrations(reactive_expert(), LAVA, 8, env_kwargs={"obs_mode": "onehot"})
    path = tmp_path_factory.mktemp("gaifo") / "lava-expert.npz"
    save_demonstrations(path, demos)
    return str(path)


def lava_gaifo(demonstrations: str) -> GaifoConfig:
    """A tiny GAIfO on the lava world (also the GPU test's setup)."""
    return (
        GaifoConfig()
        .environment(LAVA, env_config={"obs_mode": "onehot"})
        .env_runners(num_env_runners=0)
        .training(train_batch_size=200, minibatch_size=100, num_epochs=1)
        .rl_module(model_config={"fcnet_hiddens": [16]})
        .gaifo(demonstrations=demonstrations, disc_hiddens=[16], disc_batch_size=64)
        .debugging(seed=0)
    )


# ----------------------------------------------------------------------------- hand-made
def test_reward_is_gails_minus_log_one_minus_d_and_airls_logit():
    logits = torch.tensor([0.0, math.log(3.0), -20.0])  # D = 1/2, 3/4, ~0
    gail = imitation_reward(logits, "gail")
    assert gail[0].item() == pytest.approx(math.log(2.0))  # −log(1 − 1/2)
    assert gail[1].item() == pytest.approx(math.log(4.0))  # −log(1 − 3/4)
    assert gail[2].item() == pytest.approx(0.0, abs=1e-8)  # looks like the policy: no reward
    assert torch.equal(imitation_reward(logits, "airl"), logits)
    with pytest.raises(ValueError, match="reward_form='x'.*gail | airl"):
        imitation_reward(logits, "x")


def test_loss_is_half_the_bce_of_expert_rows_plus_half_of_policy_rows():
    loss, stats = gaifo_loss(torch.tensor([0.0, 0.0]), torch.tensor([0.0]))
    assert loss.item() == pytest.approx(math.log(2.0))  # D = 1/2 everywhere
    assert stats["js_estimate"].item() == pytest.approx(0.0, abs=1e-6)
    # expert logit log 3 (D = 3/4): BCE −log 3/4; policy logit −log 3 (D = 1/4): BCE −log 3/4
    loss, stats = gaifo_loss(torch.tensor([math.log(3.0)]), torch.tensor([-math.log(3.0)]))
    assert loss.item() == pytest.approx(-math.log(0.75))
    assert stats["disc_acc_real"].item() == 1.0 and stats["disc_acc_fake"].item() == 1.0
    # class-balanced: 3 expert rows weigh as much as 1 policy row
    loss, _ = gaifo_loss(torch.zeros(3), torch.tensor([-math.log(3.0)]))
    assert loss.item() == pytest.approx(0.5 * math.log(2.0) - 0.5 * math.log(0.75))


def test_features_are_s_and_s_next_optionally_their_first_state_dims():
    obs, nxt = torch.tensor([[1.0, 2.0, 9.0]]), torch.tensor([[3.0, 4.0, 9.0]])
    assert transition_features(obs, nxt).tolist() == [[1, 2, 9, 3, 4, 9]]
    assert transition_features(obs, nxt, state_dims=2).tolist() == [[1, 2, 3, 4]]
    with pytest.raises(ValueError, match="state_dims=4 exceeds the observation's 3 features"):
        transition_features(obs, nxt, state_dims=4)


def test_features_obs_next_and_obs_delta_read_the_whole_observation_then_s_next_or_its_change():
    obs, nxt = torch.tensor([[1.0, 2.0, 9.0]]), torch.tensor([[3.0, 7.0, 5.0]])
    assert transition_features(obs, nxt, 2, "obs_next").tolist() == [[1, 2, 9, 3, 7]]
    assert transition_features(obs, nxt, 2, "obs_delta").tolist() == [[1, 2, 9, 2, 5]]
    assert transition_features(obs, nxt, None, "obs_delta").tolist() == [[1, 2, 9, 2, 5, -4]]
    with pytest.raises(ValueError, match="gaifo.disc_input='sas' is not allowed; expected"):
        transition_features(obs, nxt, 2, "sas")
    assert GaifoSettings().disc_input == "s_next"  # GAIfO's default: (s, s′), as before


def test_piece_without_disc_on_batch_writes_rewards_and_leaves_d_as_it_was():
    settings = GaifoSettings(disc_on_batch=False, disc_lr=1e-1, input_norm=False)
    trainer = GaifoTrainer(settings, _demos())
    before = [p.detach().clone() for p in trainer.disc.parameters()]
    batch = {"default_policy": {
        Columns.OBS: torch.tensor([[0.0, 0], [1, 1], [2, 2]]),
        Columns.REWARDS: torch.tensor([1.0, 2.0, 0.0]),
        Columns.LOSS_MASK: torch.tensor([True, True, False]),
    }}  # fmt: skip
    GaifoRewardPiece(trainer=trainer, module_ids=("default_policy",))(rl_module=None, batch=batch)
    feats = trainer.features(torch.tensor([[0.0, 0], [1, 1]]), torch.tensor([[1.0, 1], [2, 2]]))
    expected = trainer.reward(feats).tolist() + [0.0]
    assert batch["default_policy"][Columns.REWARDS].tolist() == pytest.approx(expected)
    assert all(torch.equal(a, b) for a, b in zip(before, trainer.disc.parameters(), strict=True))
    assert GaifoSettings().disc_on_batch  # GAIfO's default: D trains on every batch


def test_trainer_learns_to_tell_expert_transitions_from_others():
    settings = GaifoSettings(disc_steps=200, disc_lr=1e-2, disc_hiddens=(16,), input_norm=False)
    trainer = GaifoTrainer(settings, _demos())
    policy = trainer.features(torch.full((8, 2), -5.0), torch.full((8, 2), -9.0))
    before = trainer.reward(policy).mean().item()
    stats = trainer.update(policy)
    assert stats["disc_acc_real"].item() == 1.0 and stats["disc_acc_fake"].item() == 1.0
    assert trainer.reward(policy).mean().item() < before  # the policy's rows now earn less
    assert trainer.reward(trainer.expert).mean().item() > 1.0


def test_piece_replaces_rewards_of_valid_rows_with_d_of_s_and_the_next_row():
    settings = GaifoSettings(reward_scale=2.0, env_reward_weight=0.5, disc_steps=1,
                             disc_lr=1e-9, input_norm=False)
    trainer = GaifoTrainer(settings, _demos())
    for p in trainer.disc.parameters():  # logit 0 everywhere: reward 2·log 2 + 0.5·r_env
        torch.nn.init.zeros_(p)
    # one episode chunk of 2 steps + bootstrap row, one of 1 step + bootstrap row
    obs = torch.tensor([[0.0, 0], [1, 1], [2, 2], [5, 5], [6, 6]])
    batch = {"default_policy": {
        Columns.OBS: obs,
        Columns.REWARDS: torch.tensor([1.0, 2.0, 0.0, 4.0, 0.0]),
        Columns.LOSS_MASK: torch.tensor([True, True, False, True, False]),
    }}
    seen = {}

    def record(features):  # what D trains on
        seen["feats"] = features
        return {}

    trainer.update = record
    GaifoRewardPiece(trainer=trainer, module_ids=("default_policy",))(rl_module=None, batch=batch)
    log2 = math.log(2.0)
    expected = [2 * log2 + 0.5, 2 * log2 + 1.0, 0.0, 2 * log2 + 2.0, 0.0]
    assert batch["default_policy"][Columns.REWARDS].tolist() == pytest.approx(expected)
    assert seen["feats"].tolist() == [[0, 0, 1, 1], [1, 1, 2, 2], [5, 5, 6, 6]]


# ----------------------------------------------------------------------------- RLlib
def _disc(algo) -> dict:
    return {k: v.clone() for k, v in algo.learner_group._learner.gaifo.disc.state_dict().items()}


def test_gaifo_trains_and_its_discriminator_survives_a_checkpoint(lava_demos, tmp_path):
    algo = lava_gaifo(lava_demos).build_algo()
    try:
        result = algo.train()
        stats = result["learners"]["gaifo"]
        assert 0 < stats["disc_loss"] < 1.0 and np.isfinite(stats["js_estimate"])
        before = _disc(algo)
        checkpoint = algo.save_to_path(str(tmp_path / "ckpt"))
        algo.train()
        moved = _disc(algo)
        assert any(not torch.equal(moved[k], before[k]) for k in before), "D did not train"
        algo.restore_from_path(checkpoint)
        after = _disc(algo)
        assert all(torch.equal(after[k], before[k]) for k in before)
    finally:
        algo.stop()


def test_gaifo_with_asor_adds_asors_bonus_after_the_imitation_reward(lava_demos):
    from rllib_asor import ray_compat as compat
    from rllib_asor.rllib.connector import AsorRewardConnector

    algo = rllib_asor.with_asor(lava_gaifo(lava_demos), seed=0).build_algo()
    try:
        pieces = [type(c) for c in compat.learner_connector(algo.learner_group._learner).connectors]
        assert pieces.index(GaifoRewardPiece) < pieces.index(AsorRewardConnector)
        result = algo.train()
        assert np.isfinite(result["asor"]["disc_loss"])
        assert np.isfinite(result["learners"]["gaifo"]["disc_loss"])
    finally:
        algo.stop()


def test_two_learners_keep_one_discriminator(lava_demos):
    algo = lava_gaifo(lava_demos).learners(num_learners=2, num_cpus_per_learner=0.5).build_algo()
    try:
        algo.train()
        states = algo.learner_group.foreach_learner(
            lambda learner: {k: v.cpu().numpy() for k, v in learner.gaifo.disc.state_dict().items()}
        )
        first, second = [s.get() for s in states]
        for k in first:
            np.testing.assert_array_equal(first[k], second[k], err_msg=k)
    finally:
        algo.stop()


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_gaifo_trains_on_a_gpu(lava_demos):
    algo = lava_gaifo(lava_demos).learners(num_gpus_per_learner=1).build_algo()
    try:
        result = algo.train()
        assert np.isfinite(result["learners"]["gaifo"]["disc_loss"])
        assert next(algo.learner_group._learner.gaifo.disc.parameters()).is_cuda
    finally:
        algo.stop()


# ----------------------------------------------------------------------------- bad input
def test_bad_input_is_one_line_naming_the_problem(tmp_path):
    with pytest.raises(ValueError, match="gaifo.disc_lr=0 is not allowed; expected a number > 0"):
        GaifoConfig().gaifo(disc_lr=0)
    with pytest.raises(ValueError, match="gaifo.disc_lrr is not a GAIfO setting"):
        GaifoConfig().gaifo(disc_lrr=1)
    config = GaifoConfig().environment(LAVA, env_config={"obs_mode": "onehot"})
    with pytest.raises(ValueError, match="GAIfO needs expert demonstrations: set gaifo"):
        config.validate()
    wrong = tmp_path / "pendulum.npz"
    save_demonstrations(wrong, _demos(dim=3))
    with pytest.raises(ValueError, match=r"expected \(15,\).*got \(3,\)"):
        config.gaifo(demonstrations=str(wrong)).validate()
    with pytest.raises(ValueError, match="do not exist"):
        config.gaifo(demonstrations=str(tmp_path / "none.npz")).validate()
