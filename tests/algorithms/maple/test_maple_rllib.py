"""MAPLE, MAPLE+ASOR and MOPO on RLlib: one update each, the bonus on real and model rows, the
checkpoint round trip, the settings' validation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from ray.rllib.algorithms.algorithm import Algorithm
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns

import rllib_asor
from rllib_asor.algorithms.maple import learner as maple_learner
from rllib_asor.algorithms.maple.settings import MapleSettings
from rllib_asor.rllib.modules import TRAINER_STATE

ENV = "rllib_asor/HopperShift-v0"
TINY = dict(
    rollout_batch_size=64,
    steps_per_iteration=2,
    ensemble_max_epochs=2,
    evaluation_interval=1,
    evaluation_episodes=1,
)


@pytest.fixture(scope="module")
def parts(hopper_offline_data) -> list[str]:
    """200 steps of uniform actions under each of the three dynamics (+ the untrained policy's,
    for the manifest's reference returns; tests/conftest.py builds it once per run)."""
    return [str(hopper_offline_data / d / "random") for d in ("original", "body_mass", "density_10")]


def _config(parts: list[str], cache: Path, cls: type | None = None, **settings):
    cls = cls or rllib_asor.MapleConfig
    return (
        cls()
        .environment(ENV)
        .offline_data(input_=parts)
        .maple(**{**TINY, "ensemble_cache": str(cache), **settings})
        .debugging(seed=0)
    )


def _module(algo: Algorithm):
    return algo.learner_group._learner.module[DEFAULT_MODULE_ID].unwrapped()


def test_one_maple_update_trains_the_networks_and_shares_the_cached_ensemble(parts, tmp_path):
    algo = _config(parts, tmp_path).build_algo()
    try:
        before = {k: v.clone() for k, v in _module(algo).nets.state_dict().items()}
        result = algo.train()
        after = _module(algo).nets.state_dict()
        assert not torch.equal(before["actor.mu.weight"], after["actor.mu.weight"])
        assert not torch.equal(
            before["value_gru.gru.weight_hh_l0"], after["value_gru.gru.weight_hh_l0"]
        )
        assert not torch.equal(before["target_q1.body.0.weight"], after["target_q1.body.0.weight"])
        stats = result["learners"][DEFAULT_MODULE_ID]
        assert np.isfinite(stats["critic_loss"]) and np.isfinite(stats["actor_loss"])
        maple = result["maple"]
        assert maple["ensemble_cached"] == 0.0 and maple["model_pool_segments"] == 64
        assert 0.0 < maple["rollout_valid_fraction"] <= 1.0
        assert np.isfinite(result["evaluation"]["mean/normalized_score"])
        ensemble = {k: v.clone() for k, v in _module(algo).ensemble.state_dict().items()}
    finally:
        algo.stop()
    # a second run on the same data and seed (MAPLE+ASOR's pair) loads the same ensemble
    paired = rllib_asor.with_asor(_config(parts, tmp_path), preset="paper", seed=0).build_algo()
    try:
        for k, v in _module(paired).ensemble.state_dict().items():
            torch.testing.assert_close(v, ensemble[k])
        assert paired.train()["maple"]["ensemble_cached"] == 1.0
    finally:
        paired.stop()


def test_maple_asor_adds_the_bonus_to_real_and_model_rows(parts, tmp_path, monkeypatch):
    seen = []
    real_losses = maple_learner.maple_losses

    def spy(nets, b, **kw):
        seen.append((b["valid"].clone(), kw["bonus"].clone()))
        return real_losses(nets, b, **kw)

    monkeypatch.setattr(maple_learner, "maple_losses", spy)
    cfg = rllib_asor.with_asor(
        _config(parts, tmp_path, evaluation_interval=0), preset="paper", lambda_=0.1, seed=0
    )
    algo = cfg.build_algo()
    try:
        result = algo.train()
    finally:
        algo.stop()
    assert len(seen) == 2
    valid, bonus = seen[-1]
    n_real = int(256 * 0.05)  # the batch holds its 12 real segments first
    assert (bonus[:n_real][valid[:n_real]] < 0).all()  # λ·log ω < 0 on real rows
    assert (bonus[n_real:][valid[n_real:]] < 0).all()  # ... and on model rows
    assert (bonus[~valid] == 0).all()
    asor = result["asor"]
    assert asor["lambda"] == pytest.approx(0.1)
    assert np.isfinite(asor["disc_loss"]) and 0.0 < asor["real_fraction"] < 1.0


def test_checkpoint_round_trip_restores_ensemble_networks_discriminator_and_statistics(
    parts, tmp_path
):
    cfg = rllib_asor.with_asor(_config(parts, tmp_path, evaluation_interval=0), seed=0)
    algo = cfg.build_algo()
    try:
        algo.train()
        path = algo.save_to_path(str(tmp_path / "ckpt"))
        state = algo.learner_group._learner.module.get_state()
    finally:
        algo.stop()
    restored = Algorithm.from_checkpoint(path)
    try:
        again = restored.learner_group._learner.module.get_state()
        disc = "asor_disc." + DEFAULT_MODULE_ID
        assert set(again) == set(state) and disc in state
        flat = {mid: dict(s) for mid, s in state.items()}
        flat[disc] = state[disc][TRAINER_STATE]["modules"]
        flat_again = {mid: dict(s) for mid, s in again.items()}
        flat_again[disc] = again[disc][TRAINER_STATE]["modules"]
        for mid in flat:
            for k, v in flat[mid].items():
                np.testing.assert_allclose(
                    np.asarray(flat_again[mid][k]), np.asarray(v), err_msg=f"{mid}/{k}"
                )
        keys = set(state[DEFAULT_MODULE_ID])
        assert {"ensemble.elite_idx", "ensemble.obs_mean", "obs_lo", "reward_range"} <= keys
        assert {
            "nets.log_alpha",
            "nets.target_q2.body.0.weight",
            "nets.policy_gru.gru.weight_ih_l0",
        } <= keys
        assert any("reward_rms" in k for k in flat[disc])  # ASOR's normalisers
        restored.train()  # and training goes on
    finally:
        restored.stop()


@pytest.mark.parametrize("keep_pool", [True, False])
def test_restored_maple_goes_on_with_its_sampler_and_optionally_its_model_pool(
    parts, tmp_path, keep_pool
):
    cfg = _config(parts, tmp_path, evaluation_interval=0, checkpoint_model_pool=keep_pool)
    algo = cfg.build_algo()
    try:
        assert algo.train()["maple"]["model_pool_segments"] == 64
        path = algo.save_to_path(str(tmp_path / "ckpt"))
        draws = algo._rng.integers(0, 1 << 30, size=8)
    finally:
        algo.stop()
    restored = Algorithm.from_checkpoint(path)
    try:
        np.testing.assert_array_equal(restored._rng.integers(0, 1 << 30, size=8), draws)
        pool = restored.train()["maple"]["model_pool_segments"]
        assert pool == (128 if keep_pool else 64)
    finally:
        restored.stop()


def test_mopo_is_maple_without_context_and_runs_statelessly(parts, tmp_path):
    algo = _config(parts, tmp_path, rllib_asor.MopoConfig, evaluation_interval=0).build_algo()
    try:
        module = _module(algo)
        assert module.settings.context is False and module.settings.horizon == 5
        assert module.nets.policy_gru is None and module.nets.value_gru is None
        algo.train()
        out = module.forward_inference({Columns.OBS: torch.zeros(3, 11)})
        assert out[Columns.ACTION_DIST_INPUTS].shape == (3, 6)
    finally:
        algo.stop()


def test_maple_policy_refuses_stateless_inference(parts, tmp_path):
    import gymnasium as gym

    env = gym.make(ENV)
    spec = _config(parts, tmp_path).get_rl_module_spec()
    spec.observation_space, spec.action_space = env.observation_space, env.action_space
    module = spec.build()
    with pytest.raises(ValueError, match="recurrent"):
        module.forward_inference({Columns.OBS: torch.zeros(1, 11)})


@pytest.mark.parametrize(
    ("settings", "match"),
    [
        ({"horizon": 0}, r"maple.horizon=0 is invalid: allowed an integer >= 1"),
        ({"real_ratio": 1.5}, r"maple.real_ratio=1.5 is invalid: allowed a number in \[0, 1\]"),
        ({"ensemble_elites": 21}, r"maple.ensemble_elites=21 is invalid: allowed an integer <= "),
        ({"horizn": 5}, r"maple.horizn is not a MAPLE setting \(did you mean 'horizon'\?\)"),
        ({"context": "yes"}, r"maple.context='yes' is invalid: allowed true or false"),
        (
            {"checkpoint_model_pool": 1},
            r"maple.checkpoint_model_pool=1 is invalid: allowed true or false",
        ),
        ({"actor_lr": float("nan")}, r"maple.actor_lr=nan is invalid: allowed a number > 0"),
        (
            {"penalty_coef": float("inf")},
            r"maple.penalty_coef=inf is invalid: allowed a number >= 0",
        ),
        ({"tau": 0}, r"maple.tau=0 is invalid: allowed a number in \(0, 1\]"),
    ],
)
def test_bad_settings_name_the_key_the_value_and_what_is_allowed(settings, match):
    with pytest.raises(ValueError, match=match):
        MapleSettings.from_dict(settings)
    with pytest.raises(ValueError, match=match):
        rllib_asor.MapleConfig().maple(**settings)


def test_a_config_without_data_says_make_datasets():
    with pytest.raises(ValueError, match="make datasets"):
        rllib_asor.MapleConfig().environment(ENV).validate()


def test_maple_asor_on_two_learners_keeps_one_state(parts, tmp_path):
    """MAPLE's own gradients (torch.autograd.grad, outside DDP's hooks) are averaged across
    Learners, and ASOR's update runs on every Learner's real rows: policy, critics,
    discriminator and statistics are the same on both ranks, also after a restore."""
    from tests.cluster.test_many_learners import _assert_same, _per_rank

    def everything(learner):
        return {
            f"{mid}/{k}": v.detach().cpu().numpy().copy()
            for mid, m in learner.module._rl_modules.items()
            for k, v in m.unwrapped().state_dict().items()
        }

    def per_rank(algo):
        calls = algo.learner_group.foreach_learner(everything)
        return [c.get() for c in sorted(calls, key=lambda c: c.actor_id)]

    def build():
        config = _config(parts, tmp_path).learners(num_learners=2, num_cpus_per_learner=0.5)
        return rllib_asor.with_asor(config, seed=0).build_algo()

    algo = build()
    try:
        for _ in range(2):
            result = algo.train()
        assert np.isfinite(result["asor"]["disc_loss"])
        states = per_rank(algo)
        _assert_same(*states, "MAPLE+ASOR ranks differ")
        asor_before = _per_rank(algo)
        checkpoint = algo.save_to_path(str(tmp_path / "ckpt"))
        # Restored into the same two Learners after one more update has moved them (a second
        # two-Learner build doubled this test's time); a restore into a freshly built MAPLE is
        # test_checkpoint_round_trip_restores_ensemble_networks_discriminator_and_statistics.
        algo.train()
        moved = _per_rank(algo)[0]
        assert any(not np.array_equal(v, asor_before[0][k]) for k, v in moved.items()), "no update"
        algo.restore_from_path(checkpoint)
        for before, after in zip(asor_before, _per_rank(algo), strict=True):
            _assert_same(before, after, "MAPLE+ASOR after restore")
    finally:
        algo.stop()
