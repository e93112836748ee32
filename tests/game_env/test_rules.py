"""Reward terms and episode metrics behave as docs/game_env.md says (real physics, scripted inputs)."""

from __future__ import annotations

import numpy as np

from game_env.sim import RaceSim
from tests.game_env.helpers import IDLE, place, sim_at

JUMP = np.array([[1, 1, 1, 0, 0, 0, 0, 0]])


def test_jump_on_flat_ground_counts_as_unnecessary():
    sim = sim_at(0, 0, 0.0, 0.0, 0.0)
    for _ in range(40):
        sim.step(JUMP)
    m = sim.episode_metrics(0)
    assert m["jumps"] >= 2 and m["unnecessary_jumps"] == m["jumps"] - (1 if sim.racers[0].in_jump else 0)
    assert m["unnecessary_jump_rate"] == m["unnecessary_jumps"] / m["jumps"] > 0


def test_standing_still_costs_stay_and_time_then_trapped():
    sim = sim_at(0, 0, 0.0, 0.0, 0.0)
    stays, times = [], []
    for _ in range(int(11.0 / 0.04)):
        _, terms, _, _ = sim.step(IDLE)
        stays.append(terms[0]["stay"])
        times.append(terms[0]["time"])
    assert all(t == -0.02 for t in times)
    assert stays[10] == 0.0 and stays[-1] == -0.01  # penalised only after 2 s
    assert sim.episode_metrics(0)["trapped"] == 1.0


def test_pressing_into_a_ledge_gets_the_wall_penalty():
    sim = RaceSim(1)
    sim.load(2, 0)
    sim.reset()
    c = sim.course
    k = next(i for i, (a, b) in enumerate(zip(c.surfaces[:-1], c.surfaces[1:], strict=True))
             if b.x0 - a.x1 < 0.05 and b.z0 - a.z1 > 0.4)
    a = c.surfaces[k]
    place(sim, a.x1 - 0.5, 0.0, a.z1)
    push = np.array([[2, 1, 0, 0, 0, 0, 0, 0]])
    walls = [sim.step(push)[1][0]["fall_or_wall"] for _ in range(30)]
    assert walls.count(-1.0) == 1


def test_goal_distance_term_rewards_progress():
    sim = sim_at(0, 0, 0.0, 0.0, 0.0)
    run = np.array([[2, 1, 0, 0, 0, 0, 0, 0]])
    gains = [sim.step(run)[1][0]["goal_distance"] for _ in range(20)]
    back = [sim.step(np.array([[0, 1, 0, 0, 0, 0, 0, 0]]))[1][0]["goal_distance"] for _ in range(20)]
    assert sum(gains) > 0 > sum(back)


def test_racers_collide_and_attack_pushes_the_other():
    sim = RaceSim(2)
    sim.load(0, 0)
    sim.reset()
    sim.data.qpos[sim.qpos_i[0]] = [0.0, 0.0, 0.65]
    sim.data.qpos[sim.qpos_i[1]] = [1.0, 0.0, 0.65]
    sim.last_pos = sim.data.qpos[sim.qpos_flat].tolist()
    idle = np.tile(IDLE, (2, 1))
    sim.step(idle)
    assert np.hypot(*(sim.pos[1, :2] - sim.pos[0, :2])) >= 0.55  # capsules do not overlap
    x1 = sim.pos[1, 0]
    attack = idle.copy()
    attack[0, 4] = 1
    sim.step(attack)
    for _ in range(30):
        sim.step(idle)
    assert sim.pos[1, 0] - x1 > 1.0
