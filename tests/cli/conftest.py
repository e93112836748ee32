"""Shared fixtures for the `rllib` CLI tests: YAML writers and one Ray session per run."""

from __future__ import annotations

import os
import textwrap
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

CARTPOLE_YAML = """
cartpole-ppo:
  env: CartPole-v1
  run: PPO
  stop: {env_runners/episode_return_mean: 150, num_env_steps_sampled_lifetime: 100000}
  config:
    lr: 0.0003
    num_env_runners: 2
    num_epochs: 6
    minibatch_size: 128
    model_config: {fcnet_hiddens: [32, 32]}
  checkpoint_config: {checkpoint_frequency: 1, checkpoint_at_end: true}
"""


@pytest.fixture
def write_yaml(tmp_path: Path) -> Callable[[str, str], str]:
    """Write a (dedented) YAML text to tmp_path/name and return its path."""

    def write(text: str, name: str = "exp.yaml") -> str:
        path = tmp_path / name
        path.write_text(textwrap.dedent(text))
        return str(path)

    return write


@pytest.fixture(scope="session")
def cli_ray() -> Iterator[None]:
    """One local Ray (4 logical CPUs, like tests/conftest.py's `ray_session`) for every
    end-to-end CLI test; the CLI reuses an initialised Ray. `address="local"` keeps a cluster
    someone else started on this machine out of it. Left running for later tests, as the shared
    fixture does."""
    import ray

    os.environ.setdefault("RAY_memory_monitor_refresh_ms", "0")
    if not ray.is_initialized():
        ray.init(address="local", num_cpus=4, include_dashboard=False, log_to_driver=False)
    yield
