"""Every registered id: makes, reports its dynamics in every info; env modules import nothing of ours."""

from __future__ import annotations

import ast
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import rllib_asor.envs  # noqa: F401  (registers the ids)
from rllib_asor.registry.envs import ENV_IDS, register_envs

ENVS_DIR = Path(rllib_asor.envs.__file__).parent
ALLOWED_ROOTS = {
    "__future__", "ast", "collections", "functools", "re", "typing", "zlib",
    "gymnasium", "numpy", "mujoco", "highway_env",
}  # fmt: skip


@pytest.mark.filterwarnings("ignore:.*Box observation space:UserWarning")
@pytest.mark.parametrize("env_id", sorted(ENV_IDS))
def test_every_id_puts_int_dynamics_id_in_every_info(env_id: str) -> None:
    env = gym.make(env_id)
    env.action_space.seed(0)
    _, info = env.reset(seed=0)
    assert isinstance(info["dynamics_id"], (int, np.integer))
    for _ in range(3):
        *_, term, trunc, info = env.step(env.action_space.sample())
        assert isinstance(info["dynamics_id"], (int, np.integer))
        if term or trunc:
            break
    env.close()


def test_register_envs_is_idempotent_and_covers_the_table() -> None:
    register_envs()
    register_envs()
    assert set(ENV_IDS) <= set(gym.registry)
    assert {
        "rllib_asor/LavaWorld-v0",
        "rllib_asor/HalfCheetahShift-v0",
        "rllib_asor/Walker2dShift-v0",
        "rllib_asor/HopperShift-v0",
        "rllib_asor/AntShift-v0",
        "rllib_asor/HighwayDensity-v0",
    } <= set(ENV_IDS)


@pytest.mark.parametrize("path", sorted(ENVS_DIR.glob("*.py")), ids=lambda p: p.name)
def test_env_modules_import_no_ray_torch_or_other_packages_of_ours(path: Path) -> None:
    roots = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            roots |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            roots.add(node.module or "")
    ours = {r for r in roots if r.startswith("rllib_asor")}
    assert all(r.startswith("rllib_asor.envs") for r in ours), ours
    # game_env.gl, the one module that imports MuJoCo without loading a GL library, is shared
    # with the race package (which imports no ray or torch either); nothing else of game_env.
    shared = {r for r in roots if r == "game_env.gl"}
    assert {r.split(".")[0] for r in roots - ours - shared} <= ALLOWED_ROOTS
