"""DARA: the classifier loss and Δr on hand-made tensors (sign and scale), the relabelled data,
MAPLE+DARA training from Python, its checkpoint round trip, and bad settings in one line."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch
from ray.rllib.core import DEFAULT_MODULE_ID

import rllib_asor
from rllib_asor.algorithms.dara.classifiers import DomainClassifiers, classifier_loss, delta_reward
from rllib_asor.algorithms.dara.relabel import dara_parts, load_classifiers
from rllib_asor.algorithms.dara.settings import DaraSettings
from rllib_asor.algorithms.dara.wiring import with_dara
from rllib_asor.algorithms.maple.data import read_part

OBS, ACT = 3, 2


def constant(sa: tuple[float, float], advantage: tuple[float, float]) -> DomainClassifiers:
    """Classifiers whose logits are the given constants (weights 0, last biases set)."""
    model = DomainClassifiers(OBS, ACT, hidden=(4,), input_noise=0.0)
    with torch.no_grad():
        for p in model.parameters():
            p.zero_()
        model.sa[-1].bias.copy_(torch.tensor(sa))
        model.advantage[-1].bias.copy_(torch.tensor(advantage))
    return model


def rows(n: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(n)
    return (
        torch.randn(n, OBS, generator=g),
        torch.randn(n, ACT, generator=g),
        torch.randn(n, OBS, generator=g),
    )


def test_delta_r_is_the_log_odds_the_next_state_adds_to_the_state_action_odds():
    s, a, s2 = rows(5)
    # (s, a, s′) says target 3:1 beyond what (s, a) says: Δr = log 3 > 0
    assert torch.allclose(
        delta_reward(constant((0, 0), (0, math.log(3))), s, a, s2), torch.full((5,), math.log(3))
    )
    # source 4:1 from s′: Δr = −log 4 < 0, the penalty DARA puts on such source rows
    d = delta_reward(constant((0, 0), (math.log(4), 0)), s, a, s2)
    assert torch.allclose(d, torch.full((5,), -math.log(4)))
    # (s, a) alone favours the target: the same dynamics, no correction
    assert torch.allclose(
        delta_reward(constant((0, math.log(2)), (0, 0)), s, a, s2), torch.zeros(5)
    )
    # clipped to ±clip
    assert torch.allclose(
        delta_reward(constant((0, 0), (0, 50.0)), s, a, s2, clip=10.0), torch.full((5,), 10.0)
    )


def test_classifier_loss_is_the_sum_of_both_cross_entropies_on_balanced_domains():
    loss, stats = classifier_loss(constant((0, 0), (0, 0)), rows(4), rows(6), noisy=False)
    assert math.isclose(loss.item(), 2 * math.log(2), rel_tol=1e-6)
    assert stats["sa_accuracy"] == pytest.approx(0.4)  # ties go to class 0: the 4 source rows
    # both say target 3:1 for every row: source rows cost log 4, target rows log 4/3
    loss, _ = classifier_loss(constant((0, math.log(3)), (0, 0)), rows(4), rows(4), noisy=False)
    each = (math.log(4) + math.log(4 / 3)) / 2
    assert math.isclose(loss.item(), 2 * each, rel_tol=1e-6)
    # the loss falls when the classifiers are trained
    model = DomainClassifiers(OBS, ACT, hidden=(16,), input_noise=0.0)
    src = tuple(x + 2.0 for x in rows(64))
    tgt = rows(64)
    opt = torch.optim.Adam(model.parameters(), lr=1e-2)
    first = classifier_loss(model, src, tgt)[0].item()
    for _ in range(100):
        loss, _ = classifier_loss(model, src, tgt)
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert loss.item() < 0.2 * first


@pytest.mark.parametrize(
    ("settings", "match"),
    [
        ({"eta": -1}, r"^dara.eta=-1 is invalid: allowed a number >= 0$"),
        ({"hidden": [0]}, r"^dara.hidden=\[0\] is invalid: allowed a list of integers >= 1$"),
        (
            {"target_dynamic": "x"},
            r"^dara.target_dynamic is not a DARA setting \(did you mean 'target_dynamics'\?\)",
        ),
    ],
)
def test_bad_settings_name_the_key_the_value_and_what_is_allowed(settings, match):
    with pytest.raises(ValueError, match=match):
        DaraSettings.from_dict(settings)


def test_dara_refuses_an_algorithm_it_is_not_wired_into():
    from ray.rllib.algorithms.cql import CQLConfig
    from ray.rllib.algorithms.ppo import PPOConfig

    with pytest.raises(
        ValueError, match=r"^DARA does not support algorithm 'PPO': supported MAPLE, MOPO, CQL$"
    ):
        with_dara(PPOConfig())
    with pytest.raises(ValueError, match=r"^DARA on CQL needs the dataset parts first"):
        with_dara(CQLConfig())


@pytest.fixture(scope="module")
def parts(hopper_offline_data) -> list[str]:
    return [
        str(hopper_offline_data / d / "random") for d in ("original", "body_mass", "density_10")
    ]


FAST = {"classifier_steps": 300}


def test_relabelled_copies_change_source_rewards_by_eta_delta_r_and_keep_target_rewards(
    parts, tmp_path
):
    settings = {**FAST, "eta": 0.5, "cache": str(tmp_path)}
    new, info = dara_parts(parts, settings, seed=0)
    assert info["cached"] == 0.0 and info["source_steps"] > 0
    assert (
        all(Path(p).is_dir() for p in new)
        and (Path(new[0]).parent.parent / "manifest.json").is_file()
    )
    model = load_classifiers(new[0])
    for old, relabelled, target in zip(parts, new, (True, False, False), strict=True):
        before, after = read_part(old), read_part(relabelled)
        assert len(before) == len(after)
        for (o, a, r, term), (o2, a2, r2, term2) in zip(before, after, strict=True):
            assert np.array_equal(o, o2) and np.array_equal(a, a2) and term == term2
            if target:
                assert np.array_equal(r, r2)
            else:
                ot = torch.as_tensor(o)
                d = delta_reward(model, ot[:-1], torch.as_tensor(a), ot[1:]).numpy()
                np.testing.assert_allclose(r2, r + 0.5 * d, rtol=1e-5, atol=1e-5)
    again, info2 = dara_parts(parts, settings, seed=0)
    assert again == new and info2["cached"] == 1.0
    plain, _ = dara_parts(parts, {**settings, "eta": 0.0}, seed=0)
    for old, p in zip(parts, plain, strict=True):
        assert all(
            np.array_equal(x[2], y[2]) for x, y in zip(read_part(old), read_part(p), strict=True)
        )


def test_target_dynamics_must_name_a_part(parts, tmp_path):
    with pytest.raises(
        ValueError,
        match=r"^dara.target_dynamics='wind' is invalid: allowed the dynamics of a dataset part \(original \| body_mass \| density_10\)$",
    ):
        dara_parts(parts, {"target_dynamics": "wind", "cache": str(tmp_path)})
    with pytest.raises(ValueError, match="DARA needs source parts"):
        dara_parts(parts[:1], {"cache": str(tmp_path)})


def _maple_dara(parts: list[str], tmp_path: Path):
    tiny = dict(
        rollout_batch_size=64,
        steps_per_iteration=2,
        ensemble_max_epochs=1,
        ensemble_members=4,
        ensemble_elites=2,
        evaluation_interval=0,
        ensemble_cache=str(tmp_path / "ens"),
    )
    config = (
        rllib_asor.MapleConfig()
        .environment("rllib_asor/HopperShift-v0")
        .offline_data(input_=parts)
        .maple(**tiny)
        .debugging(seed=0)
    )
    return with_dara(config, **FAST, eta=1.0, cache=str(tmp_path / "dara"))


def test_maple_dara_trains_from_python_and_its_checkpoint_round_trips(parts, tmp_path):
    config = _maple_dara(parts, tmp_path)
    algo = config.build_algo()
    try:
        for _ in range(2):
            result = algo.train()
        dara = result["dara"]
        assert dara["cached"] == 0.0 and 0.0 <= dara["sas_accuracy"] <= 1.0
        assert np.isfinite(result["learners"][DEFAULT_MODULE_ID]["critic_loss"])
        assert all("dara" in p or str(tmp_path) in p for p in algo._paths)
        rewards = algo._traj.rewards.copy()
        ckpt = algo.save_to_path(str(tmp_path / "ckpt"))
    finally:
        algo.stop()
    from ray.rllib.algorithms.algorithm import Algorithm

    restored = Algorithm.from_checkpoint(ckpt)
    try:
        assert restored.config.dara_settings == config.dara_settings
        assert np.array_equal(restored._traj.rewards, rewards)
        assert restored.train()["dara"]["cached"] == 1.0
    finally:
        restored.stop()


def test_cql_dara_reads_the_relabelled_copies_and_trains(parts, hopper_offline_data, tmp_path):
    from tests.data.test_offline import tiny_cql

    config = tiny_cql(hopper_offline_data, quality="random")
    dara = with_dara(config, **FAST, eta=1.0, cache=str(tmp_path))
    expected, _ = dara_parts(config.input_, {**FAST, "eta": 1.0, "cache": str(tmp_path)}, seed=0)
    assert dara.input_ == expected and config.input_ != expected
    assert dara.input_read_episodes
    algo = dara.build_algo()
    try:
        result = algo.train()
        assert np.isfinite(result["learners"][DEFAULT_MODULE_ID]["qf_loss"])
    finally:
        algo.stop()
