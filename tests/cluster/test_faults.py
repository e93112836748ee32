"""Faults with real Ray/RLlib/Tune (no mocks): a crashing env, a killed driver, bad input.

- An env raising on EnvRunner 1 kills that runner; with `with_fault_tolerance` Ray restarts it,
  RLlib brings it back into service and training goes on with ASOR metrics every iteration.
- `rllib train` SIGKILLed after a checkpoint, then `rllib train ... --resume`: step counts go
  on from the checkpoint and the ASOR modules' state is the checkpointed one.
- A corrupt checkpoint file: `rllib evaluate` must exit 2 naming the file.
"""

from __future__ import annotations

import time
import uuid

import numpy as np
import pytest
import ray
from ray import tune
from ray.rllib.utils.numpy import convert_to_numpy

from rllib_asor.rllib.faults import FaultCounter, make_faulty_env, with_fault_tolerance
from tests.cluster.helpers import LAVA, assert_asor_metrics, lava_ppo_asor


def test_with_fault_tolerance_sets_fast_restart_defaults():
    config = with_fault_tolerance(lava_ppo_asor())
    assert config.restart_failed_env_runners is True
    assert config.max_num_env_runner_restarts == 100
    assert config.delay_between_env_runner_restarts_s == 2.0
    assert config.env_runner_health_probe_timeout_s == 5.0
    # The input config is not changed.
    assert lava_ppo_asor().delay_between_env_runner_restarts_s == 60.0


@pytest.mark.parametrize("bad", [{"max_restarts": 0}, {"restart_delay_s": -1},
                                 {"probe_timeout_s": "5"}])
def test_with_fault_tolerance_rejects_bad_values(bad):
    with pytest.raises(ValueError, match=f"{next(iter(bad))}=.*allowed"):
        with_fault_tolerance(lava_ppo_asor(), **bad)


def test_env_crash_on_one_runner_restarts_it_and_training_continues(ray_session):
    name = f"fault-counter-{uuid.uuid4().hex[:8]}"
    counter = FaultCounter.options(name=name).remote()
    env_id = f"faulty-lava-{uuid.uuid4().hex[:8]}"
    tune.register_env(env_id, make_faulty_env(LAVA))
    env_config = {"fault_worker_indices": [1], "fault_after_steps": 150, "fault_max": 1,
                  "fault_counter": name}
    config = with_fault_tolerance(lava_ppo_asor(env_id, env_config), restart_delay_s=0.5)
    algo = config.build_algo()
    try:
        results = []
        t0 = time.monotonic()
        # Iteration 1 samples ~100 steps per runner; the fault fires in iteration 2.
        while time.monotonic() - t0 < 60:
            results.append(algo.train())
            assert_asor_metrics(results[-1])
            ft = results[-1]["fault_tolerance"]
            if ft["num_remote_worker_restarts"] >= 1 and ft["num_healthy_workers"] == 2:
                break
        stats = ray.get(counter.stats.remote())
        assert stats["faults"] == {1: 1}, stats  # exactly one injected crash, on runner 1
        ft = results[-1]["fault_tolerance"]
        assert ft["num_remote_worker_restarts"] >= 1, [r["fault_tolerance"] for r in results]
        assert ft["num_healthy_workers"] == 2
        # Training went on: lifetime steps grow every iteration, through the crash.
        steps = [r["num_env_steps_sampled_lifetime"] for r in results]
        assert steps == sorted(steps) and len(set(steps)) == len(steps), steps
        # The restarted runner samples again (more steps counted for runner 1 after the fault).
        assert ray.get(counter.stats.remote())["steps"][1] > 151
        # Both runners (the restarted one too) act with the learner's current policy weights.
        learner_w = convert_to_numpy(algo.learner_group.get_weights()["default_policy"])
        runner_ws = algo.env_runner_group.foreach_env_runner(
            lambda r: convert_to_numpy(r.module.get_state(inference_only=True)),
            local_env_runner=False)
        assert len(runner_ws) == 2
        for runner_w in runner_ws:
            for k, v in runner_w.items():
                np.testing.assert_allclose(v, learner_w[k], err_msg=k)
    finally:
        algo.stop()
        ray.kill(counter)
