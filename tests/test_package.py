"""Package-level promises: light imports, the dependency arrows of DESIGN.md, registered ids."""

import subprocess
import sys

import pytest


def _modules_after(statement: str) -> set[str]:
    code = f"import sys; {statement}; print(' '.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return {m.split(".")[0] for m in out.stdout.split()}


@pytest.mark.parametrize(
    ("statement", "forbidden"),
    [
        ("import rllib_asor", {"ray", "torch"}),
        ("import rllib_asor.envs", {"ray", "torch"}),
        ("import rllib_asor.asor; from rllib_asor.asor import partition", {"ray"}),
    ],
)
def test_imports_stay_light(statement, forbidden):
    assert not (_modules_after(statement) & forbidden)


def test_import_rllib_asor_registers_the_env_ids():
    import gymnasium as gym

    import rllib_asor  # noqa: F401

    for env_id in ("rllib_asor/LavaWorld-v0", "rllib_asor/HopperShift-v0", "rllib_asor/HighwayDensity-v0"):
        assert env_id in gym.registry
    env = gym.make("rllib_asor/LavaWorld-v0", lava_row=5)
    obs, info = env.reset(seed=0)
    assert info["dynamics_id"] == 5 and env.observation_space.contains(obs)
