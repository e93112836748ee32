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


@pytest.fixture(scope="module")
def race_episodes():
    """64 env steps of race episodes (20-step episodes, 2 envs, seed 3) sampled in-process by
    RLlib's env runner with race PPO's initial policy: a Learner's input. Deep-copy them before
    an update (the Learner connector extends episodes in place)."""
    from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner

    from rllib_asor.race.config import race_ppo_config

    runner = SingleAgentEnvRunner(
        config=race_ppo_config(max_episode_steps=20)
        .env_runners(num_envs_per_env_runner=2)
        .debugging(seed=3)
    )
    episodes = runner.sample(num_timesteps=64, random_actions=False)
    runner.stop()
    return episodes
