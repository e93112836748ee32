"""Each of the race's seven reward terms: its sign, its size and what triggers it
(docs/game_env.md, "Observation, action, reward, metrics"), on real physics with the racer
placed by hand (not only through the scenario fingerprint)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import game_env
from game_env.constants import FEET
from game_env.env import ObstacleRaceEnv
from game_env.sim import DECAY, RaceSim
from game_env.spaces import REWARD_TERMS
from tests.game_env.helpers import IDLE, place, sim_at

RUN = np.array([[2, 1, 0, 0, 0, 0, 0, 0]])


def step(sim, action=IDLE):
    _, terms, done, err = sim.step(action)
    assert err is None
    return terms[0], done[0]


def test_terms_are_the_seven_names_in_order_and_an_idle_step_costs_only_time():
    sim = sim_at(0, 0, 0.0, 0.0, 0.0)
    step(sim)  # the racer was placed by hand: settle its potential
    terms, done = step(sim)
    assert list(terms) == list(REWARD_TERMS) == [
        "arrive_target", "arrive_goal", "arrive_destination", "goal_distance", "fall_or_wall",
        "stay", "time",
    ]
    assert terms["time"] == -0.02 and not done
    assert {k: v for k, v in terms.items() if k not in ("time", "goal_distance")} == dict.fromkeys(
        ["arrive_target", "arrive_goal", "arrive_destination", "fall_or_wall", "stay"], 0.0
    )
    assert abs(terms["goal_distance"]) < 1e-4  # standing still: no change of the potential


def test_an_archive_point_pays_one_the_first_time_only():
    sim = sim_at(0, 0, 0.0, 0.0, 0.0)
    arch = sim.course.archives[1]
    place(sim, arch.cx, arch.cy, arch.z + 0.01)
    terms, _ = step(sim)
    assert terms["arrive_target"] == 1.0 and sim.racers[0].last_archive == 1
    assert [step(sim)[0]["arrive_target"] for _ in range(3)] == [0.0] * 3
    # high above the point (more than 2.5 m over its floor) it is not reached
    other = sim_at(0, 0, 0.0, 0.0, 0.0)
    place(other, arch.cx, arch.cy, arch.z + 3.0)
    assert step(other)[0]["arrive_target"] == 0.0


def test_an_intermediate_goal_pays_point_three_once_and_moves_the_potential_on():
    sim = sim_at(0, 0, 0.0, 0.0, 0.0)
    goal = sim.course.goals[0]
    assert sim.racers[0].next_goal == 0
    place(sim, goal.cx, goal.cy, goal.z + 0.01)
    terms, done = step(sim)
    assert terms["arrive_goal"] == pytest.approx(0.3) and not done
    assert sim.racers[0].next_goal == 1
    # the shaping of this step is measured towards goal 0 (where the racer was heading)
    x, y, z = sim.pos[0]
    gx, gy, gz = sim.goal_pos[0]
    assert terms["goal_distance"] > 0.5  # the potential jumped from far away to ≈ 1
    phi_next = math.exp(-DECAY * math.dist((x, y, z), sim.goal_pos[1]))
    assert sim.racers[0].potential == pytest.approx(phi_next)
    assert [step(sim)[0]["arrive_goal"] for _ in range(3)] == [0.0] * 3


def test_the_destination_pays_one_and_ends_the_race():
    sim = sim_at(0, 0, 0.0, 0.0, 0.0)
    d = sim.course.destination
    place(sim, d.cx, d.cy, d.z + 0.01)
    terms, done = step(sim)
    assert terms["arrive_destination"] == 1.0 and done
    assert sim.episode_metrics(0)["success"] == 1.0 and not sim.racers[0].active
    # a finished racer earns nothing more
    terms, done = step(sim)
    assert sum(terms.values()) == 0.0 and not done


def test_goal_distance_is_the_change_of_the_potential_towards_the_next_goal():
    sim = sim_at(0, 0, 0.0, 0.0, 0.0)
    step(sim)
    before = math.exp(-DECAY * math.dist(sim.pos[0], sim.goal_pos[0]))
    terms, _ = step(sim, RUN)
    after = math.exp(-DECAY * math.dist(sim.pos[0], sim.goal_pos[0]))
    assert terms["goal_distance"] == pytest.approx(after - before, abs=1e-6)
    assert terms["goal_distance"] > 0  # running towards +x, where the goals are


def test_a_fall_costs_one_and_respawns():
    sim = sim_at(0, 0, 0.0, 0.0, 0.0)
    place(sim, 0.0, 0.0, sim.fall_z - FEET - 1.0)  # below the fall line
    terms, _ = step(sim)
    assert terms["fall_or_wall"] == -1.0
    assert sim.pos[0, 2] > sim.fall_z + 1.0  # back on the course
    assert step(sim)[0]["fall_or_wall"] == 0.0


def test_stay_starts_after_two_seconds_within_half_a_metre():
    sim = sim_at(0, 0, 0.0, 0.0, 0.0)
    stays = [step(sim)[0]["stay"] for _ in range(60)]  # 2.4 s
    first = stays.index(-0.01)
    assert set(stays[:first]) == {0.0} and set(stays[first:]) == {-0.01}
    assert 2.0 / 0.04 <= first + 1 <= 2.0 / 0.04 + 2
    # moving more than 0.5 m resets the clock
    for _ in range(10):
        terms, _ = step(sim, RUN)
    assert terms["stay"] == 0.0


def test_episode_metrics_account_the_terms():
    sim = sim_at(0, 0, 0.0, 0.0, 0.0)
    total = goal = 0.0
    arch, g = sim.course.archives[0], sim.course.goals[0]
    for target in (arch, g):
        place(sim, target.cx, target.cy, target.z + 0.01)
        terms, _ = step(sim)
        total += sum(terms.values())
        goal += terms["arrive_target"] + terms["arrive_goal"] + terms["arrive_destination"]
    m = sim.episode_metrics(0)
    assert m["goal_reward"] == pytest.approx(goal) and goal == pytest.approx(1.3)
    assert m["total_reward"] == pytest.approx(total)
    assert m["episode_length"] == 2


def test_the_env_reward_is_the_sum_and_the_time_limit_truncates():
    env = ObstacleRaceEnv(map_id=0, course_seed=0, max_episode_steps=3)
    env.reset(seed=0)
    for t in range(3):
        _, reward, terminated, truncated, info = env.step(IDLE[0])
        assert reward == pytest.approx(sum(info["reward_terms"].values()))
        assert not terminated and truncated == (t == 2)
    env.close()


def test_a_fallen_racer_respawns_still_at_its_own_spot_by_the_last_archive_point():
    sim = RaceSim(5)  # racer 4 starts in the second row: an offset along x and y
    sim.load(0, 0)
    sim.reset()
    r = sim.racers[4]
    sim.data.qpos[sim.qpos_i[4]] = [1.0, 1.0, sim.fall_z - 1.0]  # racer 4 below the fall line
    r.knock_until = r.dash_until = 1e9  # knocked back and dashing when it fell
    r.launched = r.in_jump = True
    sim.last_pos = sim.data.qpos[sim.qpos_flat].tolist()
    _, terms, _, err = sim.step(np.repeat(IDLE, 5, axis=0))
    assert err is None and terms[4]["fall_or_wall"] == -1.0 and terms[0]["fall_or_wall"] == 0.0
    ax, ay, az = sim.arch_pos[r.last_archive]  # the start: no archive point reached yet
    ox, oy = sim.offsets[4]
    assert ox != 0.0 and oy != 0.0
    spot = (ax + 0.5 * ox, ay + 0.5 * oy, az + 0.05)
    assert sim.pos[4].tolist() == pytest.approx(spot, abs=1e-9)
    assert sim.vel[4].tolist() == [0.0, 0.0, 0.0]
    assert (r.knock_until, r.dash_until) == (0.0, 0.0)
    assert not (r.launched or r.grounded or r.in_jump)
    assert tuple(r.anchor) == pytest.approx(spot[:2]) and len(r.anchor) == 2
    assert r.anchor_t == pytest.approx(sim.data.time)


def test_the_parallel_env_pays_each_racer_its_terms_and_ends_each_at_its_own_time():
    env = game_env.parallel_env(num_racers=2, map_id=0, course_seed=0, max_episode_steps=3)
    env.reset(seed=0)
    first, second = env.possible_agents
    d = env.sim.course.destination
    place(env.sim, d.cx, d.cy, d.z + 0.01)  # the first racer at the destination
    _, rewards, terms, truncs, infos = env.step({a: IDLE[0] for a in env.agents})
    for a in (first, second):
        assert rewards[a] == pytest.approx(sum(infos[a]["reward_terms"].values()))
    assert infos[first]["reward_terms"]["arrive_destination"] == 1.0
    assert terms == {first: True, second: False} and truncs == {first: False, second: False}
    assert infos[first]["episode_metrics"]["success"] == 1.0
    assert "episode_metrics" not in infos[second] and env.agents == [second]
    for t in (1, 2):  # the time limit truncates the other racer at step 3, not later
        _, rewards, terms, truncs, infos = env.step({second: IDLE[0]})
        assert terms == {second: False} and truncs == {second: t == 2}
    assert infos[second]["episode_metrics"]["success"] == 0.0 and env.agents == []
    env.close()
