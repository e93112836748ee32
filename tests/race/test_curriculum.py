"""Map curriculum: the env's map choices, the stage rule, and a real PPO run that moves on."""

import gymnasium as gym
import pytest

import game_env
from rllib_asor.race.curriculum import (
    MapCurriculum,
    map_curriculum_callback,
)


def test_env_draws_only_from_a_map_list_and_set_map_choice_applies_at_reset():
    env = gym.make(game_env.ENV_ID, map_id=[2, 5], max_episode_steps=10)
    assert {env.reset(seed=s)[1]["map_id"] for s in range(20)} == {2, 5}
    env.unwrapped.set_map_choice(7)
    assert env.reset()[1]["map_id"] == 7
    env.unwrapped.set_map_choice("random")
    assert len({env.reset()[1]["map_id"] for _ in range(30)}) > 3
    par = game_env.parallel_env(2, map_id=[1, 3], max_episode_steps=10)
    assert {par.reset(seed=s)[1]["racer_0"]["map_id"] for s in range(12)} <= {1, 3}


@pytest.mark.parametrize("bad", [[], "x", [11], 2.5, [1, "a"]])
def test_bad_map_choice_names_what_is_allowed(bad):
    env = gym.make(game_env.ENV_ID, max_episode_steps=10)
    with pytest.raises(ValueError, match="allowed"):
        env.unwrapped.set_map_choice(bad)
    with pytest.raises(ValueError, match="allowed"):
        gym.make(game_env.ENV_ID, map_id=bad)


@pytest.mark.parametrize(
    ("block", "match"),
    [
        ({"stages": []}, "empty"),
        ({"stages": "random"}, "list of map choices"),
        ({"stages": [[2], [12]]}, "stage 1"),
        ({"stages": [2], "metric": "return"}, "success_rate"),
        ({"stages": [2], "threshold": 1.5}, "0 < threshold <= 1"),
        ({"stages": [2], "min_episodes": 0}, "min_episodes"),
        ({"stages": [2], "max_env_steps": "10k"}, "max_env_steps"),
        ({"stages": [2], "thresold": 0.5}, "unknown key"),
        ({"threshold": 0.5}, "'stages' is missing"),
    ],
)
def test_bad_curriculum_is_a_clear_error(block, match):
    with pytest.raises(ValueError, match=match):
        MapCurriculum.from_dict(block)


def test_stage_moves_on_when_the_recent_episodes_meet_the_threshold():
    cur = MapCurriculum(stages=[[2, 6], "random"], threshold=0.5, min_episodes=4)
    cb = map_curriculum_callback(cur)()
    pushed = []
    cb._push = lambda algorithm: pushed.append(cb.stage)  # no env runners in this test

    def result(e2, s2, e6, s6):
        return {
            "env_runners": {
                "race": {
                    "map_2": {"episodes": e2, "success_sum": s2},
                    "map_6": {"episodes": e6, "success_sum": s6},
                }
            }
        }

    for totals in [(0, 0, 0, 0), (4, 4, 2, 2)]:  # map 6 has too few episodes yet
        r = result(*totals)
        cb.on_train_result(algorithm=None, result=r)
        assert r["race"]["curriculum_stage"] == 0
        assert "curriculum_score" not in r["race"]  # not yet defined: absent, never NaN
    r = result(8, 5, 5, 2)  # latest >= 4 episodes: map 2 1/4, map 6 2/5 -> 0.325 < 0.5
    cb.on_train_result(algorithm=None, result=r)
    assert r["race"]["curriculum_score"] == pytest.approx(0.325) and not pushed
    r = result(12, 9, 9, 6)  # latest 4 episodes: map 2 4/4, map 6 4/4
    cb.on_train_result(algorithm=None, result=r)
    assert r["race"]["curriculum_stage"] == 1 and pushed == [1]
    assert cur.maps(1) == list(range(10))


def test_max_env_steps_moves_on_without_episodes():
    cb = map_curriculum_callback(MapCurriculum(stages=[3, 4], max_env_steps=100))()
    cb._push = lambda algorithm: None
    r = {"num_env_steps_sampled_lifetime": 100}
    cb.on_train_result(algorithm=None, result=r)
    assert r["race"]["curriculum_stage"] == 1


@pytest.mark.parametrize("num_racers", [1, 2], ids=["single", "multi"])
def test_ppo_run_moves_the_envs_to_the_next_stage(ray_session, num_racers):
    from rllib_asor.race.config import RaceMetricsCallback, race_ppo_config

    cur = {"stages": [[2], 3], "metric": "goal_reward", "threshold": -1.0, "min_episodes": 1}
    envs = 2 if num_racers == 1 else 1
    config = (
        race_ppo_config(num_racers, None, max_episode_steps=20, curriculum=cur)
        .env_runners(num_env_runners=0, num_envs_per_env_runner=envs)
        .training(train_batch_size=128, minibatch_size=64, num_epochs=1)
    )
    assert config.callbacks_class[0] is RaceMetricsCallback
    algo = config.build_algo()
    try:
        vec = algo.env_runner.env.unwrapped  # a vector env in both cases
        assert vec.call("map_choice") == (2,) * envs
        stages = [algo.train()["race"]["curriculum_stage"] for _ in range(2)]
        assert stages == [0, 1]
        assert vec.call("map_choice") == (3,) * envs
    finally:
        algo.stop()
