"""The glue's small promises that the Learner-level tests rarely reach (each written for a
mutant of the glue that survived them; docs/testing.md, "Mutation testing").

The metrics callbacks keep only finite numbers and drop NaN at every depth under `learners`;
a Tune run name maps to the supported algorithm it derives from; the reward rows keep their
dtype and device, and so does the bonus of an adapter's bonus rows; an episode id keeps its
own "_" (only RLlib's "_<i>" suffix is stripped); the many-Learner path moves every tensor
of an `AsorBatch` to the Learner's device; the proxy is seeded for every proxy kind.

CI has no GPU: a factory call that ignores the data's device is caught by running the code
with torch's default device set to "meta" (as tests/asor/test_device_behaviour.py does), a
dtype that ignores the data's by data in another dtype than torch's default.
"""

from __future__ import annotations

import math
import os

import gymnasium as gym
import numpy as np
import pytest
import torch
import torch.distributed as dist
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.algorithms.ppo.torch.ppo_torch_learner import PPOTorchLearner
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.algorithms.sac.torch.sac_torch_learner import SACTorchLearner
from ray.rllib.core import DEFAULT_MODULE_ID, Columns

from rllib_asor import with_asor
from rllib_asor.algorithms.sac.fast import FLAT_STORAGE, fast_off_policy
from rllib_asor.algorithms.sac.learner import FastSACTorchLearner
from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.proxy import ProxyInputs
from rllib_asor.asor.update import AsorBatch, AsorState
from rllib_asor.rllib import connector
from rllib_asor.rllib.callbacks import (
    AsorMetricsCallback,
    DropNaNLearnerStatsCallback,
    drop_nan_learner_stats,
    lift_asor_metrics,
)
from rllib_asor.rllib.connector import AsorRewardConnector
from rllib_asor.rllib.learners import AsorPPOTorchLearner, AsorSACTorchLearner
from rllib_asor.rllib.modules import AsorModule
from rllib_asor.rllib.wiring import asor_learner_class, supported_run
from tests.rllib.test_glue_behaviour import episodes, learner

NAN, INF = float("nan"), float("inf")
DISC = "asor_disc." + DEFAULT_MODULE_ID


def piece(**asor) -> AsorRewardConnector:
    """The ASOR piece on its own (no Learner): enough for its row helpers."""
    return AsorRewardConnector(asor=AsorConfig(**asor), module_ids={}, adapter=None, gamma=0.9)


# ------------------------------------------------------------------ metrics callbacks
def test_lifted_metrics_are_finite_numbers_only():
    stats = {"disc_loss": NAN, "lambda": INF, "bonus_mean": -INF, "js_estimate": "n/a",
             "disc_acc_real": 0.5, "real_fraction": 1}  # fmt: skip
    assert lift_asor_metrics({"learners": {DISC: stats}}) == {
        "disc_acc_real": 0.5,
        "real_fraction": 1.0,
    }


def test_nan_learner_stats_are_dropped_at_every_depth_and_only_under_learners():
    def result():
        return {
            "learners": {
                "p": {"num_trainable_parameters": NAN, "loss": 0.5, "deep": {"x": NAN, "y": 1.0}},
                "__all_modules__": {"inf_stays": INF},
            },
            "env_runners": {"episode_return_mean": NAN},
        }

    kept = {"p": {"loss": 0.5, "deep": {"y": 1.0}}, "__all_modules__": {"inf_stays": INF}}
    r = result()
    drop_nan_learner_stats(r)
    assert r["learners"] == kept and math.isnan(r["env_runners"]["episode_return_mean"])
    for callback in (DropNaNLearnerStatsCallback(), AsorMetricsCallback()):
        r = result()
        callback.on_train_result(result=r)
        assert r["learners"] == kept
    drop_nan_learner_stats({"learners": None})  # nothing to prune: no error
    drop_nan_learner_stats({})


# ------------------------------------------------------------------ run names
def test_a_run_name_maps_to_the_supported_algorithm_it_derives_from():
    assert supported_run("PPO") == "PPO"
    assert supported_run("FastSAC") == "SAC"  # a subclass of RLlib's SAC
    assert supported_run("MOPO") == "MAPLE"  # a subclass of MAPLE
    assert supported_run("DQN") is None  # registered, not supported
    assert supported_run("NoSuchAlgorithm") is None  # unknown


# ------------------------------------------------------------------ the Learner and the replay
def test_a_users_learner_that_adds_nothing_gets_the_algorithms_asor_learner():
    class MyPPO(PPOTorchLearner):
        pass

    assert asor_learner_class(PPOConfig().learners(learner_class=MyPPO)) is AsorPPOTorchLearner

    class Extra:  # a base ASOR's Learner does not have: ASOR would drop it
        def hook(self) -> None: ...

    class Mixed(Extra, PPOTorchLearner):
        pass

    with pytest.raises(ValueError, match="learner_class=Mixed has no ASOR Learner"):
        asor_learner_class(PPOConfig().learners(learner_class=Mixed))


def test_per_dynamics_rnd_is_refused_on_the_flat_storage_whatever_the_learner():
    episodic = {"type": "EpisodeReplayBuffer"}
    flat = fast_off_policy(
        SACConfig().learners(learner_class=SACTorchLearner).training(replay_buffer_config=episodic)
    )
    assert flat.replay_buffer_config["storage"] == FLAT_STORAGE
    with pytest.raises(ValueError, match="proxy='rnd_per_dynamics' needs each step's dynamics"):
        with_asor(flat, proxy="rnd_per_dynamics")
    # RLlib's own replay keeps each step's infos, whatever its type or the Learner
    plain = with_asor(SACConfig().training(replay_buffer_config=episodic), proxy="rnd_per_dynamics")
    assert plain.learner_class is AsorSACTorchLearner
    fast_learner = SACConfig().learners(learner_class=FastSACTorchLearner)  # prioritized replay
    with_asor(fast_learner, proxy="rnd_per_dynamics")
    with_asor(PPOConfig(), proxy="rnd_per_dynamics")  # on-policy: no replay buffer at all


def test_the_aux_optimizers_take_the_settings_learning_rates_and_weight_decay():
    lrn = learner(disc_lr=2e-3, rnd_lr=5e-3, disc_weight_decay=0.01)
    trainer = lrn.module[DISC].unwrapped().trainer
    disc, proxy = trainer.disc_optimizer, trainer.proxy_optimizer
    assert disc.param_groups[0]["lr"] == pytest.approx(2e-3)
    assert proxy.param_groups[0]["lr"] == pytest.approx(5e-3)
    assert disc.param_groups[0]["weight_decay"] == 0.01
    assert proxy.param_groups[0]["weight_decay"] == 0.0
    # each optimizer holds exactly its network's trainable parameters (not the RND target)
    trainable = {id(p) for p in trainer.proxy.parameters() if p.requires_grad}
    assert {id(p) for g in proxy.param_groups for p in g["params"]} == trainable
    assert len(trainable) < len(list(trainer.proxy.parameters()))
    assert {id(p) for g in disc.param_groups for p in g["params"]} == {
        id(p) for p in trainer.state.parameters()
    }


def test_asors_module_has_no_rllib_optimizer_and_its_minibatch_is_the_policys():
    lrn = learner()
    assert lrn.get_optimizers_for_module(DISC) == []
    assert lrn._asor_piece.minibatch_size == lrn.config.minibatch_size == 30


def test_maples_bonus_rows_get_the_configs_gamma(monkeypatch):
    from tests.rllib.test_soft_q_glue import maple_batch, maple_learner

    gammas = []
    real = connector.bonus_on_rows

    def spy(cfg, state, lam, rows, gamma):
        gammas.append(gamma)
        return real(cfg, state, lam, rows, gamma)

    monkeypatch.setattr(connector, "bonus_on_rows", spy)
    lrn = maple_learner(shaping="potential", lambda_=0.1)
    lrn.update(batch=maple_batch(lrn)[1], timesteps={"maple_gradient_steps": 0})
    assert gammas == [lrn.config.gamma]


# ------------------------------------------------------------------ dtype and device of rows
def test_the_bonus_keeps_the_rewards_dtype_and_device():
    rows = torch.tensor([0, 2])
    delta = torch.tensor([0.25, -0.5])
    for dtype in (torch.float16, torch.float64):
        pb = {Columns.REWARDS: torch.ones(2, 2, dtype=dtype, device="cpu")}
        with torch.device("meta"):
            piece()._add_to_rewards(pb, rows, delta)
        got = pb[Columns.REWARDS]
        assert got.dtype == dtype and got.device.type == "cpu"
        assert got.tolist() == [[1.25, 1.0], [0.5, 1.0]]


def _bonus_rows(dtype: torch.dtype) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(0)
    obs = torch.randn(2, 3, 4, generator=g, dtype=dtype)
    return {
        Columns.OBS: obs,
        Columns.NEXT_OBS: obs + 0.1,
        Columns.TERMINATEDS: torch.zeros(2, 3, dtype=torch.bool),
        "valid": torch.tensor([[True, True, False], [True, False, False]]),
    }


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_bonus_of_bonus_rows_keeps_the_bonus_dtype_and_device(dtype):
    cfg = AsorConfig(seed=0, disc_hiddens=[8], bonus_norm="off", shaping="potential")
    state = AsorState(cfg, 4).to(dtype)
    rows = _bonus_rows(dtype)
    expected = connector.bonus_on_rows(cfg, state, 0.5, rows, 0.9)
    other = torch.float64 if dtype == torch.float32 else torch.float32
    old = torch.get_default_dtype()
    torch.set_default_dtype(other)
    try:
        with torch.device("meta"):
            got = connector.bonus_on_rows(cfg, state, 0.5, rows, 0.9)
    finally:
        torch.set_default_dtype(old)
    assert got.dtype == expected.dtype == dtype and got.device.type == "cpu"
    assert got.shape == (2, 3) and torch.equal(got, expected)
    assert (got[~rows["valid"]] == 0).all() and (got[rows["valid"]] != 0).all()


# ------------------------------------------------------------------ episode chunks
def test_an_episode_id_keeps_its_own_underscores():
    """Only RLlib's "_<i>" suffix of the Learner's copy is stripped: ids that contain "_"
    (an offline data set's, a user's) keep the rest, so two episodes never share a key."""
    eps = episodes(0, n=3, length=4)
    eps[0].id_, eps[1].id_, eps[2].id_ = "run_a_b_3", "run_a_c_3", "run_a_c"
    valid = torch.tensor(([True] * 3 + [False]) * 3)
    chunks = piece()._chunks(eps, DEFAULT_MODULE_ID, valid)
    assert [c.key[0] for c in chunks] == ["run_a_b", "run_a_c", "run_a"]


# ------------------------------------------------------------------ several Learners
def _asor_batch() -> AsorBatch:
    x = torch.arange(12.0).reshape(4, 3)
    return AsorBatch(
        features=x,
        env_rewards=torch.arange(4.0),
        values=torch.ones(4),
        gamma=0.9,
        timestep=3.0,
        proxy_inputs=ProxyInputs(x, torch.ones(4, 2), x + 1, torch.arange(4)),
        terminateds=torch.zeros(4, dtype=torch.bool),
        next_features=x + 1,
        next_values=torch.zeros(4),
    )


def _tensors(value) -> list[torch.Tensor]:
    if isinstance(value, torch.Tensor):
        return [value]
    if isinstance(value, AsorBatch | ProxyInputs):
        return [t for v in vars(value).values() for t in _tensors(v)]
    return []


def test_moved_puts_every_tensor_of_the_batch_and_its_proxy_inputs_on_the_device():
    batch = _asor_batch()
    moved = connector._moved(batch, "meta")
    assert len(_tensors(moved)) == len(_tensors(batch)) == 10
    assert all(t.device.type == "meta" for t in _tensors(moved))
    assert moved.gamma == 0.9 and moved.timestep == 3.0
    assert all(t.device.type == "cpu" for t in _tensors(batch))  # the original is left alone
    assert connector._moved(None, "meta") is None


def test_gathered_batches_land_on_the_learners_device(tmp_path):
    os.environ.setdefault("MASTER_ADDR", "127.0.0.1")
    dist.init_process_group(
        "gloo", init_method=f"file://{tmp_path / 'store'}", rank=0, world_size=1
    )
    try:
        (got,) = connector.gather_batches(_asor_batch(), "meta")
        assert connector.gather_batches(None, "meta") == [None]
    finally:
        dist.destroy_process_group()
    assert len(_tensors(got)) == 10 and all(t.device.type == "meta" for t in _tensors(got))


# ------------------------------------------------------------------ the proxy's seed
@pytest.mark.parametrize("proxy", ["rnd", "rnd_per_dynamics", "ensemble"])
def test_every_proxy_kind_is_seeded_and_leaves_the_global_rng_alone(proxy):
    obs, act = gym.spaces.Box(-1, 1, (4,), np.float32), gym.spaces.Discrete(3)
    cfg = {"asor": AsorConfig(seed=7, proxy=proxy, rnd_hiddens=[8]).to_dict()}

    def build():
        return AsorModule(observation_space=obs, action_space=act, model_config=cfg).trainer.proxy

    torch.manual_seed(5)
    expected_next = torch.rand(1)
    torch.manual_seed(5)
    a = build()
    assert torch.rand(1).item() == expected_next.item()
    b = build()  # from another point of the global stream: the same weights
    for pa, pb in zip(a.parameters(), b.parameters(), strict=True):
        assert torch.equal(pa, pb)


def test_only_a_flat_unmasked_batch_of_the_policys_own_rows_ranks_a_random_subset():
    n, k = 8, 3
    pb = {Columns.OBS: torch.zeros(n, 2), Columns.REWARDS: torch.zeros(n)}
    rng = np.random.default_rng(0)
    subset = connector._rank_subset(pb, n, None, None, k, rng)
    assert subset is not None and subset.tolist() == sorted(set(subset.tolist()))
    assert len(subset) == k and 0 <= int(subset.min()) and int(subset.max()) < n
    # the smallest subset is one row
    assert connector._rank_subset(pb, n, None, None, 1, rng).shape == (1,)
    # every row is ranked: a loss mask (padded sequences), an adapter's own ranked columns,
    # no generator, no subset size, a subset as large as the batch, or an empty one
    for mask, ranked, rows, gen in [
        (torch.ones(n), None, k, rng),
        (None, lambda b: b, k, rng),
        (None, None, k, None),
        (None, None, None, rng),
        (None, None, n, rng),
        (None, None, 0, rng),
    ]:
        assert connector._rank_subset(pb, n, mask, ranked, rows, gen) is None
    # a column that is not one row per transition: every row is ranked
    assert connector._rank_subset({**pb, "x": torch.zeros(2 * n)}, n, None, None, k, rng) is None
    # the subset lives on the batch's device (CI has no GPU: torch's "meta" device stands in)
    meta = {key: v.to("meta") for key, v in pb.items()}
    assert connector._rank_subset(meta, n, None, None, k, rng).device.type == "meta"
