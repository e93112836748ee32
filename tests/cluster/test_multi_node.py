"""Multi-node for real: a head and two worker nodes on this machine (`ray.cluster_utils.Cluster`).

RLlib's own idiom (rllib/algorithms/tests/test_node_failures.py): nodes are added and removed
while an Algorithm trains. Each worker node offers one `runner_slot` (a custom resource) and
each EnvRunner asks for one, so the two runners land on different worker nodes and a restarted
runner can only come up on a node that has a free slot.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
import ray
from ray.cluster_utils import Cluster

from rllib_asor.algorithms.common.faults import with_fault_tolerance
from tests.cluster.helpers import RESTART_DEADLINE_S, assert_asor_metrics, lava_ppo_asor

pytestmark = pytest.mark.heavy  # starts Ray or a subprocess: scheduled first (conftest)

REPO = Path(__file__).resolve().parents[2]
RLLIB = str(Path(sys.executable).with_name("rllib"))
NODE = {"num_cpus": 1, "object_store_memory": 80 * 1024**2}
SLOT = "runner_slot"
# GCS notices a SIGKILLed node after period x threshold (Ray's default: 3 s x 5 = 15 s).
HEAD_SYSTEM_CONFIG = {"health_check_period_ms": 1000, "health_check_failure_threshold": 3}


@pytest.fixture(scope="module")
def cluster():
    """Head (1 CPU) + 2 worker nodes (1 CPU, 1 runner_slot each); the driver connects to it.

    A Ray session started earlier in this pytest process (tests/conftest.py) is shut down and,
    afterwards, started again the same way, so later tests find what they expect.
    """
    was_initialized = ray.is_initialized()
    ray.shutdown()
    c = Cluster(initialize_head=True, head_node_args={
        **NODE, "include_dashboard": False, "_system_config": HEAD_SYSTEM_CONFIG})
    # Cluster writes /tmp/ray/ray_current_cluster, which makes every plain `ray.init()` on this
    # machine join it, a test on the other pytest worker included (it then fails: num_cpus is
    # refused when joining). This module joins by address, so the file goes.
    ray._common.utils.reset_ray_address()
    try:
        c.workers = [c.add_node(**NODE, resources={SLOT: 1}) for _ in range(2)]
        c.wait_for_nodes()
        ray.init(address=c.address, log_to_driver=False, configure_logging=False)
        yield c
    finally:
        ray.shutdown()
        c.shutdown()
        if was_initialized:
            ray.init(num_cpus=4, include_dashboard=False, log_to_driver=False,
                     configure_logging=False)


def _runner_nodes(algo) -> list[str]:
    return algo.env_runner_group.foreach_env_runner(
        lambda r: ray.get_runtime_context().get_node_id(), local_env_runner=False)


# ~50 s, `make test-slow`: a lost runner restarted and training going on is
# tests/cluster/test_faults.py's env crash; joining a cluster of nodes is the CLI test below.
@pytest.mark.slow
def test_node_removed_mid_run_training_continues_and_runner_restarts_on_new_node(cluster):
    config = with_fault_tolerance(
        lava_ppo_asor(custom_resources_per_env_runner={SLOT: 1}),
        restart_delay_s=0.5, probe_timeout_s=2.0)
    algo = config.build_algo()
    try:
        nodes = _runner_nodes(algo)
        worker_ids = {n.node_id for n in cluster.workers}
        assert len(set(nodes)) == 2 and set(nodes) == worker_ids  # one runner per worker node
        results = [algo.train()]
        assert_asor_metrics(results[-1])

        cluster.remove_node(cluster.workers[0], allow_graceful=False)  # the node dies
        for _ in range(2):  # training goes on with the runner on the surviving node
            results.append(algo.train())
            assert_asor_metrics(results[-1])
        assert results[-1]["fault_tolerance"]["num_healthy_workers"] == 1

        new_node = cluster.add_node(**NODE, resources={SLOT: 1})  # a replacement node
        t0 = time.monotonic()
        while time.monotonic() - t0 < RESTART_DEADLINE_S:
            results.append(algo.train())
            assert_asor_metrics(results[-1])
            if results[-1]["fault_tolerance"]["num_healthy_workers"] == 2:
                break
        ft = results[-1]["fault_tolerance"]
        assert ft["num_healthy_workers"] == 2, [r["fault_tolerance"] for r in results]
        assert ft["num_remote_worker_restarts"] >= 1
        assert new_node.node_id in _runner_nodes(algo)  # the lost runner came back there
        steps = [r["num_env_steps_sampled_lifetime"] for r in results]
        assert steps == sorted(steps) and len(set(steps)) == len(steps), steps
    finally:
        algo.stop()


def test_cli_train_address_joins_the_running_cluster(cluster, tmp_path):
    """`rllib train ... --address HEAD` runs its trial on this cluster (no local Ray)."""
    jobs_before = {j["JobID"] for j in ray._private.state.jobs()}
    proc = subprocess.Popen(
        [RLLIB, "train", "file", str(REPO / "tuned_examples/lava/ppo-asor.yaml"), "--test",
         "--address", cluster.address, "--storage-path", str(tmp_path),
         "--num-env-runners", "0"],  # joining is the point, not the runners
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        env={**os.environ, "RAY_memory_monitor_refresh_ms": "0"})
    try:
        out, _ = proc.communicate(timeout=300)  # 150 s was not enough under load
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, out[-3000:]
    assert "Connecting to existing Ray cluster at address" in out
    assert "1 trial(s), 0 errored" in out
    # The CLI's driver was a job of this cluster.
    new_jobs = [j for j in ray._private.state.jobs() if j["JobID"] not in jobs_before]
    assert any(str(j.get("DriverPid")) == str(proc.pid) for j in new_jobs), new_jobs
    [trial] = [p for p in (tmp_path / "lava-ppo-asor-test").iterdir() if p.is_dir()]
    assert any(trial.glob("checkpoint_*/rllib_checkpoint.json"))


@pytest.mark.slow  # SAC+ASOR on two DDP Learners (and their restore): test_many_learners.py
def test_sac_asor_learners_on_two_nodes_keep_one_state(cluster):
    """Off-policy ASOR with one DDP Learner per worker node: it trains and both ranks hold the
    same discriminator, normalisers and λ (gloo across nodes)."""
    from tests.cluster.test_many_learners import _assert_same, _per_rank, _sac

    config = _sac().learners(
        num_learners=2, num_cpus_per_learner=0.5, custom_resources_per_learner={SLOT: 1}
    ).env_runners(num_env_runners=0)  # the Learners are what it checks: sample in the driver
    algo = config.build_algo()
    try:
        nodes = [c.get() for c in algo.learner_group.foreach_learner(
            lambda _: ray.get_runtime_context().get_node_id())]
        slots = {n["NodeID"] for n in ray.nodes() if n["Alive"] and n["Resources"].get(SLOT)}
        assert len(set(nodes)) == 2 and set(nodes) <= slots  # one Learner per worker node
        for _ in range(2):
            result = algo.train()
        assert result["asor"]["disc_loss"] == result["asor"]["disc_loss"]  # finite, not NaN
        _assert_same(*_per_rank(algo), "learners on two nodes differ")
    finally:
        algo.stop()
