"""Gymnasium/PettingZoo API conformance, registration, bad input and the no-ray/torch rule."""

from __future__ import annotations

import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import parallel_api_test

import game_env
from game_env.env import ObstacleRaceEnv
from game_env.spaces import EPISODE_METRICS, REWARD_TERMS


def test_gymnasium_check_env_passes_on_raw_and_made_env():
    check_env(ObstacleRaceEnv(map_id=9, max_episode_steps=60), skip_render_check=True)
    env = gym.make("game_env/ObstacleRace-v0", map_id=3, max_episode_steps=60)
    check_env(env.unwrapped, skip_render_check=True)


def test_made_env_exposes_model_data_frame_skip_and_map_id_in_info():
    env = gym.make("game_env/ObstacleRace-v0", map_id=2)
    _, info = env.reset(seed=0)
    assert info["map_id"] == 2
    assert env.unwrapped.frame_skip == 20 and env.unwrapped.model.nq >= 3
    assert abs(env.unwrapped.dt - 0.04) < 1e-12
    assert env.unwrapped.data.time == 0.0
    _, _, _, _, info = env.step(env.action_space.sample())
    assert info["map_id"] == 2 and set(info["reward_terms"]) == set(REWARD_TERMS)


def test_pettingzoo_parallel_api_test_passes():
    parallel_api_test(game_env.parallel_env(num_racers=3, map_id=4, max_episode_steps=120), num_cycles=150)


def test_random_map_choice_draws_several_maps_from_env_rng():
    env = ObstacleRaceEnv(map_id=None)
    maps = {env.reset(seed=s)[1]["map_id"] for s in range(12)}
    assert len(maps) >= 4 and maps <= set(range(game_env.NUM_MAPS))


def test_reward_equals_sum_of_info_terms_and_metrics_at_episode_end():
    env = ObstacleRaceEnv(map_id=0, course_seed=1, max_episode_steps=80)
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(80):
        _, reward, term, trunc, info = env.step(rng.integers(0, env.action_space.nvec))
        assert reward == sum(info["reward_terms"].values())
        assert list(info["reward_terms"]) == list(REWARD_TERMS)
        if term or trunc:
            break
    assert trunc and set(info["episode_metrics"]) == set(EPISODE_METRICS)
    m = info["episode_metrics"]
    assert m["success"] == 0.0 and m["episode_length"] == 80.0
    assert 0.0 <= m["unnecessary_jump_rate"] <= 1.0 and m["distance_from_cliff"] >= 0.0


def _run(env, steps: int, seed: int = 3) -> list[tuple]:
    env.reset(seed=seed)
    rng, out = np.random.default_rng(0), []
    for _ in range(steps):
        obs, reward, term, trunc, info = env.step(rng.integers(0, env.action_space.nvec))
        out.append((obs, reward, term, trunc, info))
        if term or trunc:
            break
    return out


def test_lean_step_info_leaves_out_reward_terms_and_running_metrics_and_nothing_else():
    """The same race as "full": the same observations, rewards and ends; the course keys on
    every step and the final episode metrics on the last."""
    full = _run(ObstacleRaceEnv(map_id=0, course_seed=1, max_episode_steps=60), 60)
    lean = _run(ObstacleRaceEnv(map_id=0, course_seed=1, max_episode_steps=60, step_info="lean"), 60)
    assert len(full) == len(lean) == 60 and lean[-1][3]
    for (o1, r1, te1, tr1, i1), (o2, r2, te2, tr2, i2) in zip(full, lean, strict=True):
        assert all(np.array_equal(o1[k], o2[k]) for k in o1) and (r1, te1, tr1) == (r2, te2, tr2)
        assert {k: v for k, v in i1.items() if k not in ("reward_terms", "episode_metrics")} == {
            k: v for k, v in i2.items() if k != "episode_metrics"
        }
    assert all("reward_terms" not in info and "episode_metrics" not in info for *_, info in lean[:-1])
    assert lean[-1][4]["episode_metrics"] == full[-1][4]["episode_metrics"]
    assert "reward_terms" not in lean[-1][4]


def test_lean_step_info_in_the_parallel_env_leaves_out_reward_terms():
    env = game_env.parallel_env(num_racers=2, map_id=4, max_episode_steps=30, step_info="lean")
    env.reset(seed=0)
    for _ in range(30):
        _, _, term, trunc, infos = env.step({a: env.action_space(a).sample() for a in env.agents})
        assert all("reward_terms" not in info for info in infos.values())
        if not env.agents:
            break
    assert all(set(info["episode_metrics"]) == set(EPISODE_METRICS) for info in infos.values())


def test_an_unknown_step_info_is_refused_naming_the_allowed_ones():
    with pytest.raises(ValueError, match=r"step_info='some'.*\('full', 'lean'\)"):
        ObstacleRaceEnv(step_info="some")
    with pytest.raises(ValueError, match="step_info"):
        game_env.parallel_env(num_racers=2, step_info=None)


@pytest.mark.parametrize("map_id", [-1, 10, 3.5, "3", True])
def test_unknown_map_id_raises_value_error_naming_value_and_range(map_id):
    with pytest.raises(ValueError, match=r"map_id=.*0\.\.9"):
        gym.make("game_env/ObstacleRace-v0", map_id=map_id)
    with pytest.raises(ValueError, match="map_id"):
        game_env.parallel_env(num_racers=2, map_id=map_id)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [({"num_racers": 0}, "num_racers"), ({"num_racers": 17}, "num_racers"),
     ({"max_episode_steps": 0}, "max_episode_steps"), ({"frame_skip": -2}, "frame_skip"),
     ({"render_mode": "human"}, "render_mode"), ({"course_seed": -1}, "course_seed")],
)
def test_malformed_arguments_raise_value_error_naming_them(kwargs, name):
    with pytest.raises(ValueError, match=name):
        game_env.parallel_env(**{"num_racers": 2, **kwargs})


def test_malformed_reset_options_raise_value_error():
    env = ObstacleRaceEnv()
    with pytest.raises(ValueError, match=r"map_id=12.*0\.\.9"):
        env.reset(options={"map_id": 12})
    with pytest.raises(ValueError, match="options"):
        env.reset(options="map 3")
    _, info = env.reset(options={"map_id": 5, "course_seed": 7})
    assert info == {"map_id": 5, "dynamics_id": 5, "course_seed": 7}


@pytest.mark.parametrize("action", [[3, 1, 0, 0, 0, 0, 0, 0], [1, 1, 0, 0, 0, 0, 8, 0], [1, 1, 0], "jump",
                                    [1, 1, 0, 0, 0, 0, -1, 0], [0.5, 1, 0, 0, 0, 0, 0, 0]])
def test_action_outside_space_raises_value_error_naming_it(action):
    env = ObstacleRaceEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action .* outside"):
        env.step(action)
    penv = game_env.parallel_env(num_racers=2)
    penv.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        penv.step({"racer_0": action, "racer_1": [1, 1, 0, 0, 0, 0, 0, 0]})


def test_physics_blow_up_truncates_with_warning_and_reset_recovers():
    env = ObstacleRaceEnv(map_id=0, course_seed=0)
    env.reset(seed=0)
    env.data.qvel[0] = np.nan
    with pytest.warns(RuntimeWarning, match="unstable"):
        obs, reward, term, trunc, info = env.step([1, 1, 0, 0, 0, 0, 0, 1])
    assert trunc and not term and "physics_error" in info
    assert env.observation_space.contains(obs)
    obs, _ = env.reset()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for _ in range(5):
            obs, *_ = env.step([2, 1, 0, 0, 0, 0, 0, 0])
    assert env.observation_space.contains(obs)


def test_parallel_physics_blow_up_truncates_every_racer():
    env = game_env.parallel_env(num_racers=2, map_id=1)
    env.reset(seed=0)
    env.data.qpos[1] = np.inf
    with pytest.warns(RuntimeWarning):
        _, _, _, truncs, infos = env.step({a: [1, 1, 0, 0, 0, 0, 0, 1] for a in env.agents})
    assert all(truncs.values()) and all("physics_error" in i for i in infos.values())
    assert env.agents == []
    env.reset(seed=1)
    assert len(env.agents) == 2


def test_import_game_env_imports_neither_ray_nor_torch():
    code = "import sys, game_env; import game_env.scripted; assert 'ray' not in sys.modules and 'torch' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True, cwd=str(__import__("pathlib").Path(__file__).parents[2]))


@pytest.mark.parametrize("map_id", range(10))
def test_random_play_keeps_observations_in_space_on_every_map(map_id):
    env = ObstacleRaceEnv(map_id=map_id, course_seed=map_id, max_episode_steps=150)
    obs, _ = env.reset(seed=map_id)
    rng = np.random.default_rng(map_id)
    for _ in range(150):
        action = rng.integers(0, env.action_space.nvec)
        action[0] = 2 if rng.random() < 0.7 else action[0]  # mostly forward: reach the hazards
        obs, reward, term, trunc, info = env.step(action)
        assert env.observation_space.contains(obs), {k: (v.min(), v.max()) for k, v in obs.items()}
        assert np.isfinite(reward) and "physics_error" not in info
        if term or trunc:
            break
    assert trunc or term


def test_check_env_with_rgb_array_rendering():
    check_env(ObstacleRaceEnv(map_id=1, render_mode="rgb_array", width=64, height=48, max_episode_steps=30))


def test_make_with_max_episode_steps_truncates_with_metrics():
    env = gym.make("game_env/ObstacleRace-v0", map_id=0, max_episode_steps=25)
    env.reset(seed=0)
    ends = [env.step(np.array([1, 1, 0, 0, 0, 0, 0, 1]))[2:] for _ in range(25)]
    assert not any(t or u for t, u, _ in ends[:-1])
    term, trunc, info = ends[-1]
    assert trunc and not term
    assert info["episode_metrics"]["episode_length"] == 25.0


def test_agent_and_destination_vectors_follow_the_names_in_spaces():
    from game_env.spaces import AGENT_FEATURES, DESTINATION_FEATURES, OBS_SHAPES

    assert OBS_SHAPES["agent"] == (len(AGENT_FEATURES),)
    assert OBS_SHAPES["destination"] == (len(DESTINATION_FEATURES),)
    env = ObstacleRaceEnv(map_id=0, course_seed=0, max_episode_steps=100)
    obs, _ = env.reset(seed=0)
    agent = dict(zip(AGENT_FEATURES, obs["agent"], strict=True))
    dest = dict(zip(DESTINATION_FEATURES, obs["destination"], strict=True))
    assert agent["grounded"] == 1.0 and agent["jumping"] == agent["falling"] == 0.0
    assert agent["time_fraction"] == 0.0 and agent["progress_x"] == pytest.approx(-1.0, abs=0.05)
    d = env.sim.course.destination
    assert dest["size_x"] == pytest.approx(d.hx / 10) and dest["dx"] > 0
    for _ in range(10):
        obs, *_ = env.step([2, 1, 0, 1, 0, 0, 0, 0])  # sprint along +x
    agent = dict(zip(AGENT_FEATURES, obs["agent"], strict=True))
    assert agent["time_fraction"] == pytest.approx(0.1)
    assert agent["sprinting"] == 1.0 and agent["vel_x"] > 0.3 and agent["yaw_cos"] == 1.0
