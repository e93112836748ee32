"""A user's own env, in their own module outside the package, named every way people name envs:
`rllib train file --test` trains it, `rllib evaluate` evaluates it, and a Python script with
RLlib's PPOConfig + `with_asor` trains it after a plain `gym.register`. A bare id that only the
module registers is refused with the `module:Id` to write (an unnamed module is not imported)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tests.cli.helpers import rllib_commands

pytestmark = pytest.mark.heavy  # starts Ray or a subprocess: scheduled first (conftest)

RLLIB = str(Path(sys.executable).with_name("rllib"))

MODULE = '''
import gymnasium as gym
from gymnasium.envs.classic_control.cartpole import CartPoleEnv


class VarPoleCartPole(CartPoleEnv):
    """CartPole whose pole length is drawn per episode; info["dynamics_id"] says which."""

    LENGTHS = (0.5, 1.0, 1.5)

    def __init__(self, render_mode=None):
        super().__init__(render_mode=render_mode)
        self.dynamics_id = 0

    def reset(self, *, seed=None, options=None):
        obs, info = super().reset(seed=seed, options=options)
        self.dynamics_id = int(self.np_random.integers(len(self.LENGTHS)))
        self.length = self.LENGTHS[self.dynamics_id]
        self.polemass_length = self.masspole * self.length
        return obs, {**info, "dynamics_id": self.dynamics_id}

    def step(self, action):
        obs, reward, terminated, truncated, info = super().step(action)
        return obs, reward, terminated, truncated, {**info, "dynamics_id": self.dynamics_id}


gym.register("MyVarPole-v0", entry_point="myenv:VarPoleCartPole", max_episode_steps=100)
'''


@pytest.fixture(scope="module")
def user(tmp_path_factory):
    """A folder with the user's module (on PYTHONPATH) and a different working directory."""
    root = tmp_path_factory.mktemp("user")
    (root / "code").mkdir()
    (root / "code" / "myenv.py").write_text(MODULE)
    (root / "work").mkdir()
    env = {**os.environ, "PYTHONPATH": str(root / "code"), "RAY_memory_monitor_refresh_ms": "0"}
    return root, env


def _yaml(root: Path, env_name: str, asor: bool = True) -> Path:
    path = root / "work" / f"exp-{abs(hash(env_name))}.yaml"
    lines = ["own-env:", f"    env: {env_name}", "    run: PPO",
             "    stop: {training_iteration: 2}", "    config:",
             "        train_batch_size: 256"]
    path.write_text("\n".join(lines + (["        asor: {seed: 0}"] if asor else [])) + "\n")
    return path


def _rllib(args: list[str], user_env: dict, cwd: Path, timeout: int = 300):
    return subprocess.run([RLLIB, *args], capture_output=True, text=True, timeout=timeout,
                          env=user_env, cwd=cwd)


def test_every_way_of_naming_the_env_validates(user):
    """One file, one experiment per form (one `rllib` start instead of three)."""
    root, env = user
    names = ["myenv:MyVarPole-v0", "myenv.VarPoleCartPole", "myenv:VarPoleCartPole"]
    path = root / "work" / "forms.yaml"
    path.write_text("".join(
        f"form{i}:\n    env: {name}\n    run: PPO\n    stop: {{training_iteration: 1}}\n"
        "    config: {asor: {seed: 0}}\n"
        for i, name in enumerate(names)
    ))  # fmt: skip
    proc = _rllib(["train", "file", str(path), "--dry-run"], env, root / "work")
    assert proc.returncode == 0, proc.stderr[-2000:]
    for i, name in enumerate(names):
        assert f"form{i}:\n  env: {name}\n" in proc.stdout, proc.stdout


# ~70 s, `make test-slow`: `module:Id` trained with --test (a remote runner importing the
# user's module) and evaluated is test_env_modules.py's `trained`; per-dynamics evaluation
# output is test_ab.py's; the module on PYTHONPATH resolves in the dry-run test above.
@pytest.mark.slow
def test_own_env_by_module_and_id_trains_with_test_and_is_evaluated(user):
    root, env = user
    results = root / "results"
    # One remote EnvRunner imports the module as two would (one Ray worker fewer to start).
    proc = _rllib(["train", "file", str(_yaml(root, "myenv:MyVarPole-v0")), "--test",
                   "--num-env-runners", "1", "--storage-path", str(results)], env, root / "work")
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    assert "1 trial(s), 0 errored" in proc.stdout
    ev = _rllib(["evaluate", str(results / "own-env-test"), "--episodes", "3"], env, root / "work")
    assert ev.returncode == 0, (ev.stdout + ev.stderr)[-3000:]
    assert "Traceback" not in ev.stderr
    assert "dynamics" in ev.stdout.lower()


@pytest.mark.slow  # the class path resolves and builds a runner in the dry-run test
def test_own_env_class_path_trains_with_test(user):
    root, env = user
    proc = _rllib(["train", "file", str(_yaml(root, "myenv.VarPoleCartPole", asor=False)),
                   "--test", "--storage-path", str(root / "results2")], env, root / "work")
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]


# ~60 s, `make test-slow`: a remote runner importing the user's module is
# test_env_modules.py's `trained`; `with_asor` on remote runners with a registered id is
# tests/rllib/test_ppo_asor.py::test_with_asor_makes_our_env_ids_buildable_on_remote_env_runners.
@pytest.mark.slow
def test_python_script_registers_its_env_and_trains_with_asor(user):
    root, env = user
    script = root / "work" / "train_mine.py"
    script.write_text(textwrap.dedent("""\
        import math
        import gymnasium as gym
        import ray
        from ray.rllib.algorithms.ppo import PPOConfig
        import rllib_asor

        gym.register("MyScriptPole-v0", entry_point="myenv:VarPoleCartPole", max_episode_steps=50)
        ray.init(num_cpus=2, include_dashboard=False)
        config = (PPOConfig().environment("MyScriptPole-v0")
                  .env_runners(num_env_runners=1, num_cpus_per_env_runner=0.5)
                  .training(train_batch_size=128, minibatch_size=64, num_epochs=1))
        algo = rllib_asor.with_asor(config, seed=0).build_algo()
        result = algo.train()
        assert math.isfinite(result["asor"]["disc_loss"]), result["asor"]
        print("TRAINED", result["env_runners"]["num_episodes"])
        algo.stop()
        """))
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=300, env=env, cwd=root / "work")
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    assert "TRAINED" in proc.stdout


# The only one that imports the user's module comes last (all run in one interpreter).
REFUSED = [
    ("CartPole-v9", ("unknown env id 'CartPole-v9'", "close ids: CartPole-v")),
    ("MyVarPole-v0", ("unknown env id 'MyVarPole-v0'", "did you mean 'myenv:MyVarPole-v0'")),
    ("nosuchmodule.Env", ("module 'nosuchmodule' cannot be imported", "PYTHONPATH")),
    ("myenv:NoSuchThing", ("module 'myenv' has no env class",)),
]


def test_an_env_that_cannot_run_is_refused_in_one_line(user):
    root, env = user
    commands = [["train", "file", str(_yaml(root, name)), "--dry-run"] for name, _ in REFUSED]
    procs = rllib_commands(commands, env, root / "work")
    for (name, fragments), proc in zip(REFUSED, procs, strict=True):
        assert proc.returncode == 2, (name, proc.stderr[-2000:])
        lines = [line for line in proc.stderr.splitlines() if line.strip()]
        assert len(lines) == 1 and "Traceback" not in proc.stderr, (name, proc.stderr)
        assert all(f in lines[0] for f in fragments), lines[0]
