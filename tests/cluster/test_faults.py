"""Faults with real Ray/RLlib/Tune (no mocks): a crashing env, a killed driver, bad input.

- An env raising on EnvRunner 1 kills that runner; with `with_fault_tolerance` Ray restarts it,
  RLlib brings it back into service and training goes on with ASOR metrics every iteration.
- `rllib train` SIGKILLed after a checkpoint, then `rllib train ... --resume`: step counts go
  on from the checkpoint and the ASOR modules' state is the checkpointed one.
- A corrupt checkpoint file (the algorithm config, or the ASOR discriminator's state):
  `rllib evaluate` exits 2 with one line naming the file (tests/cli covers the policy's file).
"""

from __future__ import annotations

import contextlib
import json
import os
import pickle
import shutil
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import ray
from ray import tune
from ray.rllib.utils.numpy import convert_to_numpy

from rllib_asor.algorithms.common.faults import FaultCounter, make_faulty_env, with_fault_tolerance
from rllib_asor.rllib.modules import TRAINER_STATE
from tests.cluster.helpers import LAVA, RESTART_DEADLINE_S, assert_asor_metrics, lava_ppo_asor


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
        while time.monotonic() - t0 < RESTART_DEADLINE_S:
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


# ------------------------------------------------------------------------ driver killed, resume
KILL_YAML = """
lava-kill:
  env: rllib_asor/LavaWorld-v0
  run: PPO
  stop: {training_iteration: STOP}
  config:
    train_batch_size: 200
    minibatch_size: 100
    num_epochs: 1
    lr: 0.001
    num_env_runners: 2
    num_cpus_per_env_runner: 0.5
    model_config: {fcnet_hiddens: [32, 32]}
    seed: 0
    asor: {lambda_: 0.1}
  checkpoint_config: {checkpoint_frequency: 1}
"""
STOP_ITER = 10
RLLIB = str(Path(sys.executable).with_name("rllib"))
MODULES = "learner_group/learner/rl_module"


def _results(trial: Path) -> list[dict]:
    rows = []
    for line in (trial / "result.json").read_text().splitlines():
        try:
            rows.append(json.loads(line))
        except json.JSONDecodeError:  # a line cut short by the kill
            pass
    return rows


def _checkpoints(trial: Path) -> list[Path]:
    return sorted(p.parent for p in trial.glob("checkpoint_*/rllib_checkpoint.json"))


def _learner_state(ckpt: Path) -> dict:
    """Module states of the ASOR modules and the Learner's own state (optimizers, seq no)."""
    out = {}
    for mid in ("asor_disc.default_policy", "default_policy"):
        with open(ckpt / MODULES / mid / "module_state.pkl", "rb") as f:
            out[mid] = pickle.load(f)
    out["asor"] = out.pop("asor_disc.default_policy")[TRAINER_STATE]
    with open(ckpt / "learner_group/learner/state.pkl", "rb") as f:
        out["learner"] = pickle.load(f)
    return out


def _adam_step(state: dict, mid: str) -> float:
    """Adam's step count of the policy's optimizer, or of one of ASOR's ("asor/disc_optimizer")."""
    if mid.startswith("asor/"):
        opt = state["asor"][mid.split("/")[1]]["state"]
    else:
        opt = state["learner"]["optimizer"][f"{mid}_default_optimizer"]["state"]["state"]
    return float(opt[0]["step"])


def _kill_session(proc: subprocess.Popen) -> None:
    """SIGKILL what is left of the process group we started (Ray daemons of the dead driver)."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(proc.pid, signal.SIGKILL)


@pytest.fixture(scope="module")
def killed_and_resumed(tmp_path_factory):
    """`rllib train` SIGKILLed after a few checkpoints, then `rllib train ... --resume`."""
    root = tmp_path_factory.mktemp("kill")
    yaml_path = root / "kill.yaml"
    yaml_path.write_text(KILL_YAML.replace("STOP", str(STOP_ITER)))
    storage = root / "results"
    argv = [RLLIB, "train", "file", str(yaml_path), "--storage-path", str(storage)]
    env = {**os.environ, "RAY_memory_monitor_refresh_ms": "0"}
    with open(root / "run1.log", "w") as log:
        proc = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT, env=env,
                                start_new_session=True)
    exp = storage / "lava-kill"
    try:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline and proc.poll() is None:
            trials = [p for p in exp.glob("AsorPPO_*") if p.is_dir()] if exp.is_dir() else []
            ckpts = _checkpoints(trials[0]) if trials else []
            states = list(exp.glob("experiment_state-*.json"))
            # >= 3 checkpoints and a Tune experiment snapshot taken after the 2nd newest one.
            if len(ckpts) >= 3 and states and max(s.stat().st_mtime for s in states) > (
                ckpts[-2] / "rllib_checkpoint.json"
            ).stat().st_mtime:
                break
            time.sleep(0.2)
        assert proc.poll() is None, "the run ended before it could be killed:\n" + (
            root / "run1.log").read_text()[-3000:]
        proc.send_signal(signal.SIGKILL)  # the driver only (its Ray daemons live on)
        proc.wait(timeout=30)
    finally:
        time.sleep(2)
        _kill_session(proc)
    [trial] = [p for p in exp.glob("AsorPPO_*") if p.is_dir()]
    before = _results(trial)
    at_kill = root / "at_kill"
    for ckpt in _checkpoints(trial):
        shutil.copytree(ckpt, at_kill / ckpt.name)
    kill_time = time.time()
    t0 = time.monotonic()
    with open(root / "run2.log", "w") as log:
        resumed = subprocess.Popen([*argv, "--resume"], stdout=log, stderr=subprocess.STDOUT,
                                   env=env, start_new_session=True)
        try:
            rc = resumed.wait(timeout=300)
        finally:
            _kill_session(resumed)
    return SimpleNamespace(rc=rc, log=(root / "run2.log").read_text(), trial=trial,
                           before=before, after=_results(trial), at_kill=at_kill,
                           kill_time=kill_time, resume_s=time.monotonic() - t0)


@pytest.mark.slow
def test_killed_driver_resumes_from_checkpoint_with_continuous_steps(killed_and_resumed):
    r = killed_and_resumed
    assert r.rc == 0, r.log[-3000:]
    last_before = r.before[-1]["training_iteration"]
    assert last_before < STOP_ITER  # it was killed mid-run
    new = r.after[len(r.before):]
    assert new and new[0]["iterations_since_restore"] == 1
    k = new[0]["training_iteration"] - 1  # the iteration of the checkpoint it resumed from
    print(f"killed after iteration {last_before}, resumed from iteration {k}, "
          f"resume run took {r.resume_s:.0f} s")
    assert 3 <= k <= last_before, (k, last_before)
    # Lifetime env steps go on from the checkpointed value (not from 0) ...
    at_k = next(row for row in r.before if row["training_iteration"] == k)
    sampled = new[0]["env_runners"]["num_env_steps_sampled"]
    assert new[0]["num_env_steps_sampled_lifetime"] == at_k["num_env_steps_sampled_lifetime"] + (
        sampled)
    # ... and keep growing to the stop budget.
    lifetimes = [row["num_env_steps_sampled_lifetime"] for row in new]
    assert lifetimes == sorted(lifetimes) and new[-1]["training_iteration"] == STOP_ITER
    assert new[-1]["num_env_steps_sampled_lifetime"] >= at_k["num_env_steps_sampled_lifetime"] + (
        (STOP_ITER - k) * 200)


@pytest.mark.slow
def test_resumed_learner_continues_checkpointed_asor_state(killed_and_resumed):
    """Checkpoints written after --resume extend the one it resumed from: the RND normaliser
    count, the Adam step counts of the discriminator, RND and policy and the weight sequence
    number grow by exactly one iteration's worth per iteration from the checkpointed values (a
    fresh start would begin again from one iteration's worth); the frozen RND target network is
    the checkpointed one bit for bit."""
    r = killed_and_resumed
    assert r.rc == 0, r.log[-3000:]
    k = r.after[len(r.before)]["training_iteration"] - 1
    ckpt_k = [c for c in _checkpoints(r.at_kill) if _learner_state(c)["learner"][
        "weights_seq_no"] == k]
    assert ckpt_k, f"no checkpoint of iteration {k} on disk at kill time"
    saved = _learner_state(ckpt_k[0])
    resumed = [c for c in _checkpoints(r.trial) if c.stat().st_mtime > r.kill_time]
    assert resumed, "no checkpoint written by the resumed run"
    nxt = _learner_state(resumed[0])
    j = nxt["learner"]["weights_seq_no"]  # its training iteration
    assert k < j <= STOP_ITER
    proxy_k, proxy_j = saved["asor"]["modules"], nxt["asor"]["modules"]
    count_k = float(proxy_k["proxy.rnd.obs_rms.count"])
    count_j = float(proxy_j["proxy.rnd.obs_rms.count"])
    assert count_j == pytest.approx(count_k * j / k, rel=0.01), (k, j, count_k, count_j)
    for mid in ("asor/disc_optimizer", "asor/proxy_optimizer", "default_policy"):
        assert _adam_step(nxt, mid) == pytest.approx(_adam_step(saved, mid) * j / k), mid
    for key, value in proxy_k.items():
        if key.startswith("proxy.rnd.target."):
            np.testing.assert_array_equal(np.asarray(proxy_j[key]), np.asarray(value), key)


# ---------------------------------------------------------------------------- bad checkpoints
@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory, ray_session):
    """A PPO+ASOR lava checkpoint written by Algorithm.save_to_path (no remote runners)."""
    path = tmp_path_factory.mktemp("ckpt") / "checkpoint_000000"
    algo = lava_ppo_asor().env_runners(num_env_runners=0).build_algo()
    try:
        algo.save_to_path(str(path))
    finally:
        algo.stop()
    return path


def _evaluate(argv: list[str], capsys) -> tuple[int, str]:
    from rllib_asor.cli.main import main

    rc = main(argv)
    return rc, capsys.readouterr().err


def _corrupt(checkpoint: Path, tmp_path: Path, rel: str) -> tuple[Path, Path]:
    copy = tmp_path / checkpoint.name
    shutil.copytree(checkpoint, copy)
    target = copy / rel
    with open(target, "r+b") as f:
        f.truncate(max(1, target.stat().st_size // 2))
    return copy, target


def test_evaluate_truncated_ctor_file_exits_2_naming_it(checkpoint, tmp_path, capsys):
    copy, target = _corrupt(checkpoint, tmp_path, "class_and_ctor_args.pkl")
    rc, err = _evaluate(["evaluate", str(copy), "--episodes", "1"], capsys)
    assert rc == 2, err[-2000:]
    assert str(target) in err and len(err.strip().splitlines()) == 1, err[-2000:]


def test_evaluate_truncated_asor_module_state_exits_2_naming_it(checkpoint, tmp_path, capsys):
    copy, target = _corrupt(checkpoint, tmp_path,
                            f"{MODULES}/asor_disc.default_policy/module_state.pkl")
    rc, err = _evaluate(["evaluate", str(copy), "--episodes", "1"], capsys)
    assert rc == 2, err[-2000:]
    [line] = err.strip().splitlines()
    assert str(target) in line and "damaged" in line, err[-2000:]
