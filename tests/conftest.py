"""Shared fixtures: one small local Ray instance per test session, one small offline dataset."""

import os
from pathlib import Path

import pytest

os.environ.setdefault("RAY_memory_monitor_refresh_ms", "0")
os.environ.setdefault("RAY_DISABLE_DOCKER_CPU_WARNING", "1")
os.environ.setdefault("MUJOCO_GL", "egl")
# Two cores: torch's intra-op threads fight the env runners and each other (a batch-1 forward
# went from ~5 ms to 200 ms under load with 2 threads).
os.environ.setdefault("OMP_NUM_THREADS", "1")


# Tests that request these start Ray (actors, a Tune run, an RLlib Algorithm) or build a
# dataset: seconds to a minute each, where most tests take milliseconds. Files that start Ray
# or a subprocess otherwise say so with `pytestmark = pytest.mark.heavy`.
_HEAVY_FIXTURES = frozenset({"ray_session", "cli_ray", "hopper_offline_data"})


def _heavy(item: pytest.Item) -> bool:
    return bool(_HEAVY_FIXTURES.intersection(item.fixturenames)) or (
        item.get_closest_marker("heavy") is not None
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Files with a heavy test run first, each file kept whole and in its order, so that the two
    `make test` workers (`--dist worksteal`) end on short tests and finish together."""
    heavy = {item.path for item in items if _heavy(item)}
    items.sort(key=lambda item: item.path not in heavy)


@pytest.fixture(scope="session", autouse=True)
def _one_torch_thread():
    import torch

    torch.set_num_threads(1)


@pytest.fixture(scope="session")
def ray_session():
    """A fresh local Ray with 4 logical CPUs (2 real cores are enough for tiny runs).

    `address="local"` so that a `ray start` cluster elsewhere on the machine is ignored.
    """
    import ray

    if not ray.is_initialized():
        ray.init(
            address="local",
            num_cpus=4,
            include_dashboard=False,
            log_to_driver=False,
            configure_logging=False,
        )
    yield ray


@pytest.fixture(scope="session")
def hopper_offline_data(ray_session, tmp_path_factory) -> Path:
    """A tiny HopperShift dataset, built once per run for the tests that only read it
    (tests/data, tests/algorithms/maple): 200 steps of uniform actions (`random`) and 200 of
    an untrained SAC policy (`expert`) under each of the three dynamics."""
    from rllib_asor.data.collect import collect

    out = tmp_path_factory.mktemp("hopper-offline")
    return collect(
        "rllib_asor/HopperShift-v0",
        out,
        200,
        qualities=("random", "expert"),
        train_steps=0,
        log=lambda *_: None,
    )
