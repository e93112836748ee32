"""ASOR with two DDP Learners (gloo, CPU): it trains, and every piece of its state is the same
on both ranks after an update and after a checkpoint round trip (docs/algorithm.md, "Many
Learners")."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.algorithms.sac import SACConfig

import rllib_asor
from rllib_asor.algorithms.common.ddp import SortedModuleGradientsMixin

FINITE = ("disc_loss", "disc_acc", "aug_reward_mean", "lambda", "real_fraction", "rnd_loss")


def _asor_state(learner: Any) -> dict[str, np.ndarray]:
    """Every parameter and buffer of the ASOR modules of one Learner, by name."""
    out = {}
    for mid, module in learner.module._rl_modules.items():
        if mid.startswith("asor_"):
            for name, value in module.unwrapped().state_dict().items():
                out[f"{mid}/{name}"] = value.detach().cpu().numpy().copy()
    return out


def _per_rank(algo: Any) -> list[dict[str, np.ndarray]]:
    calls = algo.learner_group.foreach_learner(_asor_state)
    states = [c.get() for c in sorted(calls, key=lambda c: c.actor_id)]
    assert len(states) == 2
    return states


def _assert_same(a: dict[str, np.ndarray], b: dict[str, np.ndarray], what: str) -> None:
    assert a.keys() == b.keys(), what
    differ = [k for k in a if not np.array_equal(a[k], b[k])]
    assert not differ, f"{what}: {differ}"


def _ppo() -> Any:
    config = (
        PPOConfig()
        .environment("CartPole-v1")
        .env_runners(num_env_runners=1, num_cpus_per_env_runner=0.5)
        .learners(num_learners=2, num_cpus_per_learner=0.5)
        .training(train_batch_size_per_learner=128, minibatch_size=64, num_epochs=2)
        .rl_module(model_config={"fcnet_hiddens": [32]})
        .debugging(seed=0)
    )
    # lambda_ auto and rnd: the auto-λ integral and the RND normaliser are state too.
    return rllib_asor.with_asor(config, seed=0, lambda_="auto", lambda_warmup=False)


def _sac() -> Any:
    config = (
        SACConfig()
        .environment("Pendulum-v1", env_config={"max_episode_steps": 50})
        .env_runners(num_env_runners=1, num_cpus_per_env_runner=0.5)
        .learners(num_learners=2, num_cpus_per_learner=0.5)
        .training(
            num_steps_sampled_before_learning_starts=64,
            train_batch_size_per_learner=32,
            replay_buffer_config={"type": "EpisodeReplayBuffer", "capacity": 10_000},
        )
        # 16 env steps per update and 80 per iteration: 5 two-Learner updates an iteration (by
        # default one step per update and 100 steps per iteration, and the test took 70 s).
        .env_runners(rollout_fragment_length=16)
        .reporting(min_sample_timesteps_per_iteration=80, min_time_s_per_iteration=0)
        .rl_module(model_config={"fcnet_hiddens": [32]})
        .debugging(seed=0)
    )
    return rllib_asor.with_asor(config, seed=0, real_source="batch")


def _escp() -> Any:
    config = (
        rllib_asor.EscpConfig()
        .environment("rllib_asor/HalfCheetahShift-v0", env_config={"max_episode_steps": 40})
        .env_runners(num_env_runners=1, num_cpus_per_env_runner=0.5)
        .learners(num_learners=2, num_cpus_per_learner=0.5)
        .escp(history_len=4, rmdm_min_replay=0)
        .training(num_steps_sampled_before_learning_starts=80, train_batch_size_per_learner=32)
        .reporting(min_sample_timesteps_per_iteration=80)
        .rl_module(model_config={"fcnet_hiddens": [32]})
        .debugging(seed=0)
    )
    return rllib_asor.with_asor(config, seed=0, real_source="batch")


def _local_sampling(make: Any) -> Any:
    """`make()` sampling in the driver: what this test checks lives in the two Learners, and a
    remote EnvRunner is one more process to start per build (tests/cluster/test_faults.py and
    test_multi_node.py train with remote runners)."""
    return make().env_runners(num_env_runners=0)


@pytest.mark.parametrize(
    "make",
    [
        pytest.param(_ppo, id="ppo"),
        pytest.param(_sac, id="sac"),
        # ~60 s, `make test-slow`: ESCP's Learner adds its encoder to SAC's; the ASOR state
        # across two DDP Learners is [sac]'s path (AsorTrainer, tests/asor/test_trainer_ddp.py).
        pytest.param(_escp, id="escp", marks=pytest.mark.slow),
    ],
)
def test_asor_trains_on_two_learners_with_one_state(make, ray_session, tmp_path):
    algo = _local_sampling(make).build_algo()
    try:
        for _ in range(2):
            result = algo.train()
        asor = result["asor"]
        assert all(math.isfinite(asor[k]) for k in FINITE), asor
        before = _per_rank(algo)
        _assert_same(*before, "ranks differ after updates")
        disc = [k for k in before[0] if "disc." in k and "weight" in k]
        assert disc, sorted(before[0])
        if make is _ppo:  # each rank's statistics saw both ranks' rows: every env step sampled
            (count,) = [v for k, v in before[0].items() if k.endswith("state.reward_rms.count")]
            assert count == pytest.approx(result["num_env_steps_sampled_lifetime"], abs=1.0)
        checkpoint = algo.save_to_path(str(tmp_path / "ckpt"))
        # Restored into the same two Learners after one more update has moved them on (a second
        # two-Learner build per case doubled this test's time); restoring into freshly built
        # Learners is checked per algorithm on one Learner: tests/rllib/test_ppo_asor.py
        # (test_checkpoint_restores_aux_weights_and_normaliser), tests/algorithms/escp/
        # test_escp_training.py (test_checkpoint_round_trip_is_bit_exact), test_fast_sac.py.
        algo.train()
        moved = _per_rank(algo)
        assert any(not np.array_equal(moved[0][k], before[0][k]) for k in disc), "no update"
        algo.restore_from_path(checkpoint)
        after = _per_rank(algo)
        _assert_same(before[0], after[0], "rank 0 after restore")
        _assert_same(before[1], after[1], "rank 1 after restore")
        result = algo.train()
        assert all(math.isfinite(result["asor"][k]) for k in FINITE)
    finally:
        algo.stop()


class _Base:
    """A Learner whose per-module gradients record the order they were asked for."""

    def __init__(self) -> None:
        self._temp_losses: dict[tuple[str, str], Any] = {}
        self.order: list[str] = []

    def compute_gradients(self, loss_per_module: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        (module_id,) = loss_per_module
        assert all(k[0] == module_id for k in self._temp_losses)
        self._temp_losses.clear()
        self.order.append(module_id)
        return {module_id: loss_per_module[module_id]}


class _Sorted(SortedModuleGradientsMixin, _Base):
    pass


def test_module_gradients_run_in_sorted_order_whatever_the_dict_order():
    learner = _Sorted()
    modules = ["policy_b", "asor_disc.policy_b", "policy_a", "asor_proxy.policy_b"]
    for mid in modules:
        learner._temp_losses[(mid, "default_optimizer_loss")] = 0.0
    losses = {m: i for i, m in enumerate(modules)} | {"__all_modules__": 9}
    grads = learner.compute_gradients(losses)
    assert learner.order == sorted(modules)
    assert grads == {m: i for i, m in enumerate(modules)}
    learner._temp_losses[("ghost", "default_optimizer_loss")] = 0.0
    with pytest.raises(RuntimeError, match="ghost"):
        learner.compute_gradients({"policy_a": 1})
