"""Each mechanic does what docs/game_env.md says, within a stated tolerance (real MuJoCo, no mocks)."""

from __future__ import annotations

import numpy as np

from game_env.constants import FEET
from tests.game_env.helpers import IDLE, course_with, sim_at


def test_conveyor_carries_idle_racer_at_belt_speed_within_10_percent():
    seed, belt = course_with(3, "boxes", lambda b: b.kind == "conveyor" and abs(b.belt[0]) < 0.1)
    sim = sim_at(3, seed, belt.cx, -0.5 * np.sign(belt.belt[1]) * belt.hy, belt.cz + belt.hz)
    vels = []
    for k in range(12):
        sim.step(IDLE)
        if k >= 4:
            vels.append(sim.vel[0, :2].copy())
    v = np.mean(vels, axis=0)
    assert np.allclose(v, belt.belt, atol=0.1 * np.hypot(*belt.belt)), (v, belt.belt)


def test_trampoline_apex_matches_launch_height_within_5_percent():
    seed, tramp = course_with(8, "trampolines", lambda t: t.tilt < np.radians(3))
    sim = sim_at(8, seed, tramp.cx - 0.6, tramp.cy, tramp.top + 0.02)
    apex = -np.inf
    for _ in range(40):
        sim.step(IDLE)
        apex = max(apex, sim.pos[0, 2] - FEET)
    assert abs((apex - tramp.top) - tramp.height) <= 0.05 * tramp.height, (apex - tramp.top, tramp.height)


def test_hammer_knock_back_distance_matches_map_within_15_percent():
    seed, ham = course_with(7, "hammers")
    sim = sim_at(7, seed, ham.px, ham.py + 1.5, ham.floor)
    hit_at = None
    for _ in range(200):
        sim.step(IDLE)
        knocked = sim.data.time < sim.racers[0].knock_until
        if hit_at is None and knocked:
            hit_at = sim.pos[0, :2].copy()
        elif hit_at is not None and np.hypot(*sim.vel[0, :2]) < 0.05:
            break
    assert hit_at is not None, "the hammer never hit the racer"
    slid = np.hypot(*(sim.pos[0, :2] - hit_at))
    assert abs(slid - ham.knock) <= 0.15 * ham.knock, (slid, ham.knock)


def test_collapsing_tile_drops_after_its_delay():
    seed, tile = course_with(6, "tiles", lambda t: t.collapses)
    sim = sim_at(6, seed, tile.cx, tile.cy, tile.top + 0.01)
    k = sim.course.tiles.index(tile)
    z0 = sim.data.mocap_pos[sim.tiles.mocap[k], 2]
    dt = sim.frame_skip * sim.model.opt.timestep
    for _ in range(int((tile.delay + 1.0) / dt)):
        sim.step(IDLE)
        t = sim.data.time
        z = sim.data.mocap_pos[sim.tiles.mocap[k], 2]
        trigger = sim.tiles.trigger[k]
        if t < trigger + tile.delay - 1e-9:
            assert z == z0, (t, trigger, z)
        elif t > trigger + tile.delay + dt:
            assert z < z0 - 1e-3, (t, trigger, z)
    assert trigger <= 2 * dt, "the racer standing on the tile did not start its timer"
    assert sim.data.mocap_pos[sim.tiles.mocap[k], 2] < z0 - 0.5


def test_fall_respawns_at_last_archive_point_with_fall_penalty():
    sim = sim_at(0, 0, 0.0, 0.0, 0.0)
    arch = sim.course.archives[0]
    from tests.game_env.helpers import place

    place(sim, arch.cx, arch.cy, arch.z + 0.01)
    _, terms, _, _ = sim.step(IDLE)
    assert terms[0]["arrive_target"] == 1.0 and sim.racers[0].last_archive == 0
    place(sim, arch.cx, sim.course.width, arch.z + 0.5)  # beside the course: falls
    fall = None
    for _ in range(100):
        _, terms, _, _ = sim.step(IDLE)
        if terms[0]["fall_or_wall"] < 0:
            fall = terms[0]["fall_or_wall"]
            break
    assert fall == -1.0
    assert np.hypot(*(sim.pos[0, :2] - [arch.cx, arch.cy])) < 1.5
    assert abs(sim.pos[0, 2] - FEET - arch.z) < 0.2


def test_racer_stands_still_when_idle_on_plain_floor():
    sim = sim_at(0, 0, 0.0, 0.0, 0.0)
    for _ in range(25):
        sim.step(IDLE)
    assert np.hypot(*sim.pos[0, :2]) < 0.02


def test_balloon_pushed_and_springs_back_or_bursts():
    seed, bal = course_with(4, "balloons")
    sim = sim_at(4, seed, bal.x - 2.0, bal.y, bal.z - 0.75)
    k = sim.course.balloons.index(bal)
    run = np.array([[2, 1, 0, 0, 0, 0, 0, 0]])
    qx = sim.idx.balloon_qpos[k, 0]
    moved = 0.0
    for _ in range(25):
        sim.step(run)
        moved = max(moved, abs(sim.data.qpos[qx] - bal.x))
    if bal.burst:
        assert sim.balloons.burst[k]
    else:
        assert moved > 0.1
        for _ in range(100):
            sim.step(IDLE)
