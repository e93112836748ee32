"""Env names resolve as Python resolves modules from where the user runs: the current folder is
importable for every form (`module:Id`, `module:Class`, `module.Class`) in `rllib train`,
`rllib ab` and `rllib evaluate`, and no file is imported unless the name names its module: a
file that mentions the id and has an import side effect stays unimported by every command."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.cli.helpers import rllib_commands

pytestmark = pytest.mark.heavy  # starts Ray or a subprocess: scheduled first (conftest)

RLLIB = str(Path(sys.executable).with_name("rllib"))

MYENVS = '''
import gymnasium as gym
import numpy as np


class PointReach(gym.Env):
    """A point mass pushed towards the origin; its mass changes per episode."""

    def __init__(self, config=None):
        self.observation_space = gym.spaces.Box(-10.0, 10.0, (2,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.mass = float(self.np_random.choice([0.5, 1.0, 2.0]))
        self.pos = self.np_random.uniform(-1, 1, 2).astype(np.float32)
        self.t = 0
        return self.pos.copy(), {"dynamics_id": self.mass}

    def step(self, action):
        self.pos = np.clip(self.pos + np.asarray(action, np.float32) / self.mass, -10, 10)
        self.t += 1
        reward = -float(np.linalg.norm(self.pos))
        return self.pos.copy(), reward, False, self.t >= 20, {"dynamics_id": self.mass}


gym.register("MyPointReach-v0", entry_point="myenvs:PointReach")
'''

SIDE_EFFECT = '''
# A training script without a __main__ guard that names the env id.
import pathlib
pathlib.Path(__file__).with_name("IMPORTED").write_text("imported")
ENV = "MyPointReach-v0"
'''


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """The user's folder: their env module, a script with an import side effect that names
    the id, and an environment without PYTHONPATH (only the current folder can help)."""
    root = tmp_path_factory.mktemp("point")
    (root / "myenvs.py").write_text(MYENVS)
    (root / "train_point.py").write_text(SIDE_EFFECT)
    (root / "elsewhere").mkdir()
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["RAY_memory_monitor_refresh_ms"] = "0"
    return root, env


def _yaml(root: Path, env_name: str, config: str = "") -> str:
    path = root / f"exp-{abs(hash((env_name, config)))}.yaml"
    path.write_text(
        f"point:\n  env: {env_name}\n  run: PPO\n  stop: {{training_iteration: 1}}\n"
        f"  config: {{train_batch_size: 128, minibatch_size: 64, num_epochs: 1{config}}}\n"
    )
    return str(path)


def _rllib(args: list[str], env: dict, cwd: Path, timeout: int = 400):
    return subprocess.run(
        [RLLIB, *args], capture_output=True, text=True, timeout=timeout, env=env, cwd=cwd
    )


def _one_line(proc, *fragments: str) -> str:
    assert proc.returncode == 2, (proc.stdout + proc.stderr)[-2000:]
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return lines[0]


def _not_imported(root: Path) -> None:
    assert not (root / "IMPORTED").exists(), "a file the user did not name was imported"


def test_every_form_naming_the_module_resolves_from_its_folder(folder):
    """One file, one experiment per form (one `rllib` start instead of three)."""
    root, env = folder
    names = ["myenvs:MyPointReach-v0", "myenvs:PointReach", "myenvs.PointReach"]
    path = root / "forms.yaml"
    path.write_text("".join(
        f"form{i}:\n  env: {name}\n  run: PPO\n  stop: {{training_iteration: 1}}\n"
        for i, name in enumerate(names)
    ))  # fmt: skip
    proc = _rllib(["train", "file", str(path), "--dry-run"], env, root)
    assert proc.returncode == 0, proc.stderr[-2000:]
    for i, name in enumerate(names):
        assert f"form{i}:\n  env: {name}\n" in proc.stdout, proc.stdout
    _not_imported(root)


def test_a_bare_id_imports_nothing_and_ab_imports_the_module_from_its_folder(folder):
    """A bare id imports nothing and says how to name the module; `rllib ab` reaches the env
    build (the module imported from the current folder) with an env_config the env refuses.
    One interpreter: the two bare ids first, as they import nothing."""
    root, env = folder
    bad_config = _yaml(root, "myenvs:MyPointReach-v0", ", env_config: {mass: 3}, asor: {seed: 0}")
    bare, close, here = rllib_commands(
        [
            ["train", "file", _yaml(root, "MyPointReach-v0"), "--dry-run"],
            ["train", "file", _yaml(root, "MyPointReach-v1"), "--dry-run"],
            ["ab", bad_config, "--seeds", "2", "--test"],
        ],
        env,
        root,
    )
    _one_line(bare, "unknown env id 'MyPointReach-v0'", "did you mean 'myenvs:MyPointReach-v0'",
              "'mymodule:MyPointReach-v0'".replace("mymodule", "myenvs"),
              "current folder and on PYTHONPATH")  # fmt: skip
    _one_line(close, "unknown env id 'MyPointReach-v1'", "'mymodule:MyPointReach-v1'")
    _one_line(here, "cannot be built with {'mass': 3}")
    _not_imported(root)


@pytest.fixture(scope="module")
def trained(folder) -> Path:
    """`rllib train file --test` on the module's env, run from the module's folder."""
    root, env = folder
    results = root / "results"
    # One remote EnvRunner imports the module as two would (one Ray worker fewer to start).
    proc = _rllib(["train", "file", _yaml(root, "myenvs:MyPointReach-v0"), "--test",
                   "--num-env-runners", "1", "--storage-path", str(results)], env, root)  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    assert "1 trial(s), 0 errored" in proc.stdout
    return results / "point-test"


def test_train_and_evaluate_from_the_modules_folder(folder, trained):
    root, env = folder
    ev = _rllib(["evaluate", str(trained), "--episodes", "2"], env, root)
    assert ev.returncode == 0, (ev.stdout + ev.stderr)[-3000:]
    assert "Traceback" not in ev.stderr and "episodes: 2" in ev.stdout
    _not_imported(root)


def test_from_another_folder_ab_and_evaluate_say_where_they_looked(folder, trained):
    """Both in one interpreter started in another folder: neither can import the module."""
    root, env = folder
    plain = _yaml(root, "myenvs:MyPointReach-v0", ", asor: {seed: 0}")
    there, away = rllib_commands(
        [["ab", plain, "--seeds", "2", "--test"], ["evaluate", str(trained), "--episodes", "2"]],
        env,
        root / "elsewhere",
    )
    _one_line(there, "module 'myenvs' cannot be imported", "run from the module's folder")
    _one_line(away, "module 'myenvs' cannot be imported", "run from the module's folder")
    _not_imported(root)
