"""Race tests use tests/conftest.py's `ray_session`, always on a fresh local Ray instance."""

import os

import pytest


@pytest.fixture(scope="session")
def _ray_address_local():
    """Make `ray.init()` start a local instance even when a `ray start`ed cluster runs here
    (ray.init() would connect to it and refuse `num_cpus`)."""
    old = os.environ.get("RAY_ADDRESS")
    os.environ["RAY_ADDRESS"] = "local"
    return old


@pytest.fixture(scope="session")
def ray_session(_ray_address_local, ray_session):
    """The session's Ray (tests/conftest.py), started with RAY_ADDRESS=local, which is undone."""
    if _ray_address_local is None:
        os.environ.pop("RAY_ADDRESS", None)
    else:
        os.environ["RAY_ADDRESS"] = _ray_address_local
    return ray_session
