"""Every algorithm we ship, alone and with ASOR, trains with its Learner on a GPU.

Marked `gpu` and skipped without CUDA. Each case builds the small setup the CPU tests of that
algorithm use (imported from them, so the two stay alike), moves the Learner to the GPU
(`num_gpus_per_learner=1`, a local Learner, no env-runner processes), trains a few
iterations and checks that the metrics are finite and that the policy and every ASOR module
(discriminator, normalisers, archive, λ, proxy) live on cuda. PPO+ASOR also runs with one
remote GPU Learner and with two Learners sharing the GPU (0.5 each), and a checkpoint written
on the GPU restores on the CPU and back. The whole set takes a few minutes on one GPU.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

import rllib_asor

pytestmark = [
    pytest.mark.gpu,
    pytest.mark.skipif(
        not torch.cuda.is_available(), reason="needs CUDA: torch.cuda.is_available() is False"
    ),
]

HOPPER = "rllib_asor/HopperShift-v0"
NAN_BY_DESIGN = ("num_trainable_parameters", "num_non_trainable_parameters")
"""RLlib 2.60 reports these NaN from the second iteration of a plain run (on a CPU as well)."""


# ----------------------------------------------------------------------------- the setups
def lava(asor: bool) -> Any:
    from tests.rllib.test_ppo_asor import lava_ppo, lava_ppo_config

    return lava_ppo(preset="robust") if asor else lava_ppo_config()


def race(asor: bool) -> Any:
    from rllib_asor.race.config import RACE_ASOR_OBS_KEYS, race_ppo_config
    from tests.race.test_race_ppo import tiny_race_ppo

    if asor:
        return tiny_race_ppo(1, RACE_ASOR_OBS_KEYS)
    return (  # tiny_race_ppo without ASOR
        race_ppo_config(num_racers=1, map_id=0, max_episode_steps=40)
        .env_runners(num_env_runners=0)
        .training(train_batch_size=200, minibatch_size=100, num_epochs=1)
        .debugging(seed=0)
    )


def sac(asor: bool) -> Any:
    from tests.rllib.test_sac_and_multi_agent import sac_config

    config = sac_config("Pendulum-v1")
    return rllib_asor.with_asor(config, lambda_=0.05, proxy="ensemble") if asor else config


def escp(asor: bool) -> Any:
    from tests.algorithms.escp.test_escp_training import _config

    return rllib_asor.with_asor(_config(), seed=0) if asor else _config()


@pytest.fixture(scope="module")
def hopper_data(ray_session, tmp_path_factory) -> Path:
    """200 steps per dynamics and quality, as tests/data/test_offline.py collects them."""
    from rllib_asor.data.collect import collect

    out = tmp_path_factory.mktemp("gpu-offline")
    return collect(HOPPER, out, 200, qualities=("random", "expert"), train_steps=0,
                   log=lambda *_: None)


def cql(data: Path, asor: bool) -> Any:
    from ray.rllib.algorithms.cql import CQLConfig

    from rllib_asor.algorithms.cql.offline import offline_input

    config = (
        CQLConfig()
        .env_runners(num_env_runners=0)
        .training(train_batch_size_per_learner=64, bc_iters=0, lr=None)
        .reporting(min_time_s_per_iteration=0, min_train_timesteps_per_iteration=0)
    )
    offline_input(config, data, dataset_num_iters_per_learner=2)
    return rllib_asor.with_asor(config, seed=0) if asor else config


def maple(data: Path, asor: bool, tmp_path: Path, mopo: bool = False) -> Any:
    from tests.algorithms.maple.test_maple_rllib import _config

    parts = [str(data / d / "random") for d in ("original", "body_mass", "density_10")]
    cls = rllib_asor.MopoConfig if mopo else rllib_asor.MapleConfig
    config = _config(parts, tmp_path, cls)
    return rllib_asor.with_asor(config, seed=0) if asor else config


# ---------------------------------------------------------------------------- the checks
def on_gpu(config: Any, learners: int = 0, gpus: float = 1) -> Any:
    return config.learners(num_learners=learners, num_gpus_per_learner=gpus)


def _devices(learner: Any) -> dict[str, list[str]]:
    """Device types of every parameter and buffer, per module of one Learner."""
    return {
        mid: sorted({t.device.type for t in module.state_dict().values()})
        for mid, module in learner.module._rl_modules.items()
    }


def _finite(section: dict[str, Any], skip: tuple[str, ...] = ()) -> list[str]:
    """The keys of `section` (not in `skip`) whose number is NaN or infinite."""
    bad = []
    for key, value in section.items():
        if isinstance(value, dict) or key in skip:
            continue
        if isinstance(value, int | float | np.floating) and not math.isfinite(float(value)):
            bad.append(key)
    return bad


def train_on_gpu(config: Any, iterations: int = 2, learners: int = 0, gpus: float = 1) -> dict:
    """Train `iterations` with the Learner(s) on the GPU (`gpus=0`: on the CPU, to check these
    checks on a machine without one); check devices and metrics."""
    expect = "cuda" if gpus > 0 else "cpu"
    algo = on_gpu(config, learners, gpus).build_algo()
    try:
        for _ in range(iterations):
            result = algo.train()
        calls = algo.learner_group.foreach_learner(_devices)
        per_learner = [c.get() for c in calls]
    finally:
        algo.stop()
    assert len(per_learner) == max(learners, 1)
    for devices in per_learner:
        assert devices and all(kinds == [expect] for kinds in devices.values()), devices
    learner_stats = result["learners"]
    assert learner_stats, "no Learner results: nothing was trained"
    for mid, stats in learner_stats.items():
        if isinstance(stats, dict):
            assert not _finite(stats, NAN_BY_DESIGN), (mid, _finite(stats, NAN_BY_DESIGN))
    if any(mid.startswith("asor_") for mid in per_learner[0]):
        asor = result["asor"]
        assert {"lambda", "disc_loss", "aug_reward_mean"} <= set(asor)
        # critic_ev is NaN until the critic's explained variance can be measured
        assert not _finite(asor, skip=("critic_ev",)), _finite(asor, skip=("critic_ev",))
    return result


# ---------------------------------------------------------------------------- the cases
ONLINE: dict[str, tuple[Callable[[bool], Any], int]] = {
    "ppo-lava": (lava, 2),
    "ppo-race": (race, 2),
    "sac": (sac, 3),  # learning starts after 64 sampled steps
    "escp": (escp, 2),
}


@pytest.mark.parametrize("asor", [False, True], ids=["alone", "asor"])
@pytest.mark.parametrize("name", sorted(ONLINE))
def test_online_algorithm_trains_with_its_learner_on_the_gpu(ray_session, name, asor) -> None:
    make, iterations = ONLINE[name]
    train_on_gpu(make(asor), iterations)


@pytest.mark.parametrize("asor", [False, True], ids=["alone", "asor"])
def test_cql_trains_with_its_learner_on_the_gpu(ray_session, hopper_data, asor) -> None:
    train_on_gpu(cql(hopper_data, asor), 2)


@pytest.mark.parametrize("asor", [False, True], ids=["alone", "asor"])
@pytest.mark.parametrize("mopo", [False, True], ids=["maple", "mopo"])
def test_maple_and_mopo_train_with_the_learner_on_the_gpu(
    ray_session, hopper_data, tmp_path, mopo, asor
) -> None:
    result = train_on_gpu(maple(hopper_data, asor, tmp_path, mopo), 2)
    assert 0.0 < result["maple"]["rollout_valid_fraction"] <= 1.0


@pytest.mark.parametrize(
    ("name", "learners", "gpus"),
    [("ppo-lava", 1, 1), ("ppo-race", 1, 1), ("ppo-lava", 2, 0.5)],
    ids=["lava-1-remote", "race-1-remote", "lava-2-learners-share-the-gpu"],
)
def test_ppo_asor_trains_on_remote_gpu_learners(ray_session, name, learners, gpus) -> None:
    make, iterations = ONLINE[name]
    train_on_gpu(make(True), iterations, learners=learners, gpus=gpus)


def _asor_state(algo: Any) -> dict[str, np.ndarray]:
    learner = algo.learner_group._learner
    return {
        f"{mid}/{k}": v.detach().cpu().numpy()
        for mid, module in learner.module._rl_modules.items()
        if mid.startswith("asor_")
        for k, v in module.state_dict().items()
    }


def test_a_checkpoint_written_on_the_gpu_restores_on_the_cpu_and_back(ray_session, tmp_path):
    checkpoint_round_trip(tmp_path)


def checkpoint_round_trip(tmp_path: Path, gpus: float = 1) -> None:
    """PPO+ASOR saved on the GPU, restored on the CPU, trained, saved, restored on the GPU
    (`gpus=0`: both on the CPU, to check these checks without a GPU)."""
    expect = "cuda" if gpus > 0 else "cpu"
    gpu = on_gpu(lava(True), gpus=gpus).build_algo()
    cpu = lava(True).learners(num_learners=0, num_gpus_per_learner=0).build_algo()
    try:
        gpu.train()
        saved = _asor_state(gpu)
        assert any(k.endswith("archive.size") and v.sum() > 0 for k, v in saved.items())
        gpu.save_to_path(tmp_path / "from-gpu")
        cpu.restore_from_path(tmp_path / "from-gpu")
        restored = _asor_state(cpu)
        assert restored.keys() == saved.keys()
        for key, value in saved.items():
            np.testing.assert_array_equal(restored[key], value, err_msg=key)
        devices = _devices(cpu.learner_group._learner)
        assert all(kinds == ["cpu"] for kinds in devices.values()), devices
        cpu.train()  # and it trains on from there
        cpu.save_to_path(tmp_path / "from-cpu")
        gpu.restore_from_path(tmp_path / "from-cpu")
        back = _asor_state(gpu)
        for key, value in _asor_state(cpu).items():
            np.testing.assert_array_equal(back[key], value, err_msg=key)
        devices = _devices(gpu.learner_group._learner)
        assert all(kinds == [expect] for kinds in devices.values()), devices
        gpu.train()
    finally:
        gpu.stop()
        cpu.stop()
