"""Highway traffic density: check_env, density really changes the traffic, observation."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import rllib_asor.envs  # noqa: F401  (registers the ids)
from rllib_asor.envs.traffic import DEFAULT_DENSITIES, HighwayDensityEnv


def test_check_env_passes() -> None:
    check_env(HighwayDensityEnv(), skip_render_check=True)


def test_registered_id_obs_is_flat_finite_box_with_ego_speed() -> None:
    env = gym.make("rllib_asor/HighwayDensity-v0", density=1.0)
    obs, info = env.reset(seed=0)
    assert obs.shape == (25,) and obs.dtype == np.float32
    assert np.all(np.isfinite(env.observation_space.low)) and np.all(obs <= 1)
    # ego row: presence 1, vx = speed / (2 * 40 m/s) after normalisation (25 m/s at start)
    assert obs[0] == 1.0 and obs[3] == pytest.approx(info["speed"] / 80.0)
    assert info["density"] == 1.0 and info["dynamics_id"] == 100
    env.close()


def test_density_changes_number_of_vehicles_near_the_ego() -> None:
    env = HighwayDensityEnv()
    near = {}
    for d in (0.5, 2.0):
        counts = []
        for seed in range(3):
            _, info = env.reset(seed=seed, options={"density": d})
            ego = env.env.vehicle
            assert len(env.env.road.vehicles) == 1 + info["vehicles_count"]
            counts.append(
                sum(
                    abs(v.position[0] - ego.position[0]) < 100
                    for v in env.env.road.vehicles
                    if v is not ego
                )
            )
        near[d] = np.mean(counts)
    assert near[2.0] >= 2 * near[0.5] > 0


def test_density_is_drawn_from_the_set_per_episode() -> None:
    env = HighwayDensityEnv()
    seen = {env.reset(seed=s)[1]["density"] for s in range(16)}
    assert seen == set(DEFAULT_DENSITIES)


def test_episode_truncates_at_duration_with_discrete_actions() -> None:
    env = HighwayDensityEnv(density=0.5, duration=4, flatten=False)
    obs, _ = env.reset(seed=1)
    assert obs.shape == (5, 5) and env.action_space.n == 5
    for _ in range(4):
        obs, reward, term, trunc, info = env.step(1)
        assert np.isfinite(reward) and env.observation_space.contains(obs)
        if term:
            assert info["crashed"]
            break
    assert term or trunc


@pytest.mark.parametrize(
    ("kwargs", "key"),
    [
        ({"densities": (1.0, -0.5)}, "densities"),
        ({"densities": ()}, "densities"),
        ({"density": 0}, "density"),
        ({"duration": 0}, "duration"),
        ({"config": {"vehicles_count": 5}}, "vehicles_count"),
    ],
)
def test_bad_options_raise_value_error_naming_key(kwargs: dict, key: str) -> None:
    with pytest.raises(ValueError, match=key):
        HighwayDensityEnv(**kwargs)
