"""The race simulator: N racers in one MuJoCo scene, batched controls, rules and observations.

``RaceSim`` is shared by the Gymnasium env (N = 1) and the PettingZoo env (N racers). It knows
nothing about either API: it takes an (N, 8) action array and returns arrays.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from game_env import mechanics
from game_env.constants import (
    ATTACK_KNOCK,
    ATTACK_RANGE,
    COOLDOWN,
    DASH_SPEED,
    DASH_TIME,
    FALL_DEPTH,
    FEET,
    FRAME_SKIP,
    JUMP_SPEED,
    RUN_SPEED,
    SPRINT_SPEED,
)
from game_env.grids import VOID, CourseGrids
from game_env.scene import load_scene, spawn_offsets
from game_env.spaces import REWARD_TERMS

STAY_S = 2.0  # stationary this long (moved < STAY_DIST) -> stay penalty
STAY_DIST = 0.5
TRAPPED_S = 10.0  # no new best progress this long -> trapped
WALL_STEPS = 25  # env steps pressing into a wall -> wall penalty
DECAY = 0.05  # goal-distance shaping: potential exp(-DECAY * distance)
REWARDS = {"arrive_target": 1.0, "arrive_goal": 0.3, "arrive_destination": 1.0, "fall_or_wall": -1.0,
           "stay": -0.01, "time": -0.02}
_BAD = [int(mujoco.mjtWarning.mjWARN_BADQPOS), int(mujoco.mjtWarning.mjWARN_BADQVEL),
        int(mujoco.mjtWarning.mjWARN_BADQACC)]
_DIRS = np.array([[math.cos(k * math.pi / 4), math.sin(k * math.pi / 4)] for k in range(8)])


class RaceSim:
    """N racers on one course. ``load`` a course, ``reset``, then ``step`` with (N, 8) actions."""

    def __init__(self, num_racers: int = 1, frame_skip: int = FRAME_SKIP, max_episode_steps: int = 1000) -> None:
        self.n = num_racers
        self.frame_skip = frame_skip
        self.max_episode_steps = max_episode_steps
        self.key: tuple[int, int] | None = None

    # --- course ------------------------------------------------------------------------
    def load(self, map_id: int, course_seed: int) -> None:
        """Build (or reuse) the scene of (map_id, course_seed)."""
        if self.key == (map_id, course_seed):
            return
        self.key = (map_id, course_seed)
        self.map_id, self.course_seed = map_id, course_seed
        course, model, idx = load_scene(map_id, course_seed, self.n)
        self.course, self.model, self.idx = course, model, idx
        self.data = mujoco.MjData(model)
        self.grids = CourseGrids(course, self.n)
        ng = model.ngeom
        self.hammers = mechanics.Hammers(course, idx)
        self.tramps = mechanics.Trampolines(course)
        self.tiles = mechanics.Tiles(course, idx, self.grids, ng)
        self.balloons = mechanics.Balloons(course, model, idx)
        self.belt = np.zeros((ng + 1, 2))
        self.belt[:ng] = idx.geom_belt
        self.geom2racer = np.full(ng + 1, -1, np.intp)
        self.geom2racer[idx.racer_geom] = np.arange(self.n)
        self.qpos_i = idx.racer_qpos
        self.qvel_i = idx.racer_qvel
        self.ctrl_i = idx.racer_ctrl.ravel()
        self.offsets = np.concatenate([spawn_offsets(self.n), np.zeros((self.n, 1))], axis=1)
        c = course
        self.arch_lo, self.arch_hi = _zone_boxes(c.archives)
        self.goal_lo, self.goal_hi = _zone_boxes(c.goals)
        d = c.destination
        self.dest = np.array([d.cx, d.cy, d.z])
        self.dest_rot = np.array([[math.cos(d.yaw), math.sin(d.yaw)], [-math.sin(d.yaw), math.cos(d.yaw)]])
        self.dest_half = np.array([d.hx, d.hy])
        self.goal_pos = np.array([[z.cx, z.cy, z.z + FEET] for z in [*c.goals, d]])
        self.arch_pos = np.array([[z.cx, z.cy, z.z + FEET] for z in c.archives] + [[*c.start[:2], c.start[2] + FEET]])
        self.fall_z = c.floor_min - FALL_DEPTH
        self.inv_len = 2.0 / c.length
        self.dest_vec = np.array([0, 0, 0, math.sin(d.yaw), math.cos(d.yaw), 0.0, d.hx / 10, d.hy / 10, 0.003],
                                 np.float32)

    # --- episode -----------------------------------------------------------------------
    def reset(self) -> dict[str, np.ndarray]:
        """Racers back on the start pad, hazards back to their initial state."""
        n = self.n
        mujoco.mj_resetData(self.model, self.data)
        self.model.opt.disableactuator = 0
        self.tiles.reset()
        self.grids.reset_tiles()
        self.grids.reset_zones()
        self.balloons.reset()
        self.hammers.pose(self.data, 0.0)
        mujoco.mj_forward(self.model, self.data)
        self.steps = 0
        self.active = np.ones(n, bool)
        self.success = np.zeros(n, bool)
        self.yaw = np.zeros(n)
        self.grounded = np.ones(n, bool)
        self.support = np.full(n, -1, np.intp)
        self.launched = np.zeros(n, bool)
        self.carry = np.zeros((n, 2))
        self.knocked_until = np.zeros(n)
        self.dash_until = np.zeros(n)
        self.dash_vel = np.zeros((n, 2))
        self.ready_t = np.zeros(n)
        self.prop = np.zeros(n, bool)
        self.sprint = np.zeros(n, bool)
        self.last_archive = np.full(n, len(self.course.archives))  # index into arch_pos (start)
        self.arch_reached = np.zeros((n, len(self.course.archives)), bool)
        self.goal_reached = np.zeros((n, len(self.course.goals)), bool)
        self.anchor = self.pos[:, :2].copy()
        self.anchor_t = np.zeros(n)
        self.best_x = self.pos[:, 0].copy()
        self.best_t = np.zeros(n)
        self.wall = np.zeros(n, np.intp)
        self.in_jump = np.zeros(n, bool)
        self.jump_z0 = np.zeros(n)
        self.jump_t0 = np.zeros(n)
        self.jump_needed = np.zeros(n, bool)
        self.jumps = np.zeros(n, np.intp)
        self.useless_jumps = np.zeros(n, np.intp)
        self.trapped = np.zeros(n, bool)
        self.cliff_sum = np.zeros(n)
        self.cliff_cnt = np.zeros(n)
        self.goal_reward = np.zeros(n)
        self.total_reward = np.zeros(n)
        self.length = np.zeros(n, np.intp)
        self.next_goal = np.zeros(n, np.intp)
        self.potential = np.exp(-DECAY * self._goal_dist(self.pos))
        self._warn = self._bad_count()
        return self.observe()

    @property
    def pos(self) -> np.ndarray:
        """(N, 3) racer centre positions."""
        return self.data.qpos[self.qpos_i]

    @property
    def vel(self) -> np.ndarray:
        return self.data.qvel[self.qvel_i]

    def _bad_count(self) -> int:
        return int(self.data.warning.number[_BAD].sum())

    def _goal_dist(self, pos: np.ndarray) -> np.ndarray:
        return np.linalg.norm(self.goal_pos[self.next_goal] - pos, axis=1)

    # --- one env step ------------------------------------------------------------------
    def step(self, actions: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, str | None]:
        """Advance one env step. Returns (obs, terms (7, N), done (N,), physics error or None).

        ``done`` marks racers that reached the destination this step; time limits are the
        caller's business (``self.steps`` counts env steps).
        """
        data, n = self.data, self.n
        t0 = data.time
        act = self.active
        a = actions
        move = (a[:, :2] - 1).astype(float)
        move[a[:, 7] == 1] = 0.0
        norm = np.hypot(move[:, 0], move[:, 1])
        moving = norm > 0
        move /= np.maximum(norm, 1.0)[:, None]
        self.sprint = (a[:, 3] == 1) & moving
        speed = np.where(self.sprint, SPRINT_SPEED, RUN_SPEED)
        if moving.any():
            self.yaw = np.where(moving, np.arctan2(move[:, 1], move[:, 0]), self.yaw)
        knocked = t0 < self.knocked_until
        ready = (t0 >= self.ready_t) & act & ~knocked
        ref = np.where(self.grounded[:, None], self.belt[self.support],
                       np.where(self.launched[:, None], self.carry, 0.0))
        target = ref + move * speed[:, None]
        dash = (a[:, 5] == 1) & self.prop & ready
        if dash.any():
            self.dash_vel[dash] = DASH_SPEED * _DIRS[a[dash, 6]]
            self.dash_until[dash] = t0 + DASH_TIME
            self.prop[dash] = False
            self.ready_t[dash] = t0 + COOLDOWN
        dashing = t0 < self.dash_until
        if dashing.any():
            target[dashing] = self.dash_vel[dashing]
        target[~act] = 0.0
        data.ctrl[self.ctrl_i] = target.ravel()
        vel_i = self.qvel_i
        jump = (a[:, 2] == 1) & self.grounded & ready
        if jump.any():
            data.qvel[vel_i[jump, 2]] = JUMP_SPEED
            self.grounded[jump] = False
            self.ready_t[jump] = t0 + COOLDOWN
            self.jumps[jump] += 1
            self.in_jump |= jump
            self.jump_z0[jump] = self.pos[jump, 2]
            self.jump_t0[jump] = t0
            self.jump_needed[jump] = False
        if n > 1:
            self._attack((a[:, 4] == 1) & ready, t0)
        knocked = t0 < self.knocked_until
        self.model.opt.disableactuator = int((np.left_shift(1, np.arange(n)) * (knocked | ~act)).sum()) if (
            knocked.any() or not act.all()) else 0
        self.hammers.pose(data, t0 + 0.5 * self.frame_skip * self.model.opt.timestep)
        mujoco.mj_step(self.model, data, nstep=self.frame_skip)
        self.steps += 1
        if self._bad_count() != self._warn or not np.isfinite(data.qpos).all():
            return self.observe(), np.zeros((len(REWARD_TERMS), n)), np.zeros(n, bool), (
                f"MuJoCo physics became unstable at t={data.time:.3f}s (bad qpos/qvel/qacc)")
        return self._after_physics(move, speed, t0, data.time)

    def _attack(self, attack: np.ndarray, t: float) -> None:
        if not attack.any():
            return
        pos = self.pos[:, :2]
        for i in np.flatnonzero(attack):
            rel = pos - pos[i]
            dist = np.hypot(rel[:, 0], rel[:, 1])
            victims = (dist < ATTACK_RANGE) & (dist > 1e-6) & self.active
            victims[i] = False
            for j in np.flatnonzero(victims):
                self.knock(j, rel[j] / dist[j], ATTACK_KNOCK, t)
            self.ready_t[i] = t + COOLDOWN

    def knock(self, i: int | np.ndarray, direction: np.ndarray, distance, t: float) -> None:
        """Knock racer(s) ``i`` back along unit ``direction`` so they slide ``distance`` m."""
        v0 = mechanics.knock_speed(distance)
        d = np.asarray(direction)
        self.data.qvel[self.qvel_i[i, 0]] = v0 * d[..., 0]
        self.data.qvel[self.qvel_i[i, 1]] = v0 * d[..., 1]
        self.knocked_until[i] = t + mechanics.knock_duration(distance)
        self.dash_until[i] = 0.0
        self.launched[i] = False

    def _contacts(self) -> np.ndarray:
        """Read contacts once: set ``grounded``/``support``; return geoms racers touched."""
        data = self.data
        self.support[:] = -1
        nc = data.ncon
        if not nc:
            self.grounded[:] = False
            return np.zeros(0, np.intp)
        con = data.contact
        g = con.geom[:nc]
        nz = con.frame[:nc, 2]
        r0, r1 = self.geom2racer[g[:, 0]], self.geom2racer[g[:, 1]]
        m0 = (r0 >= 0) & (nz < -0.5)
        m1 = (r1 >= 0) & (nz > 0.5)
        self.support[r0[m0]] = g[m0, 1]
        self.support[r1[m1]] = g[m1, 0]
        self.grounded = self.support >= 0
        touched = np.concatenate((g[r0 >= 0, 1], g[r1 >= 0, 0]))
        return touched

    def _after_physics(self, move, speed, t0, t1):
        n = self.n
        terms = np.zeros((len(REWARD_TERMS), n))
        act = self.active
        touched = self._contacts()
        self.balloons.touch(touched)
        self.tiles.update(self.data, self.support, t1)
        pos = self.pos
        vel_i = self.qvel_i
        # Landing ends a trampoline flight; pads launch grounded racers.
        self.launched &= ~self.grounded
        on_pad, pad = self.tramps.on_pad(pos)
        launch = on_pad & self.grounded & act & (self.vel[:, 2] < 0.5)
        if launch.any():
            v = self.tramps.vel[pad[launch]]
            self.data.qvel[vel_i[launch, 2]] = v[:, 2]
            self.data.qvel[vel_i[launch, 0]] = v[:, 0]
            self.carry[launch] = v[:, :2]
            self.launched |= launch
            self.grounded[launch] = False
            self.jump_needed[launch] = True
        hit, direction, dist = self.hammers.hits(pos, t0, t1)
        hit &= act & (t1 >= self.knocked_until)
        if hit.any():
            self.knock(np.flatnonzero(hit), direction[hit], dist[hit], t1)
        # Falls: respawn at the last archive point.
        fell = (pos[:, 2] < self.fall_z) & act
        if fell.any():
            terms[4, fell] += REWARDS["fall_or_wall"]
            self._respawn(np.flatnonzero(fell), t1)
            pos = self.pos
        x, y = pos[:, 0], pos[:, 1]
        feet = pos[:, 2] - FEET
        floor = self.grids.floor_height(x, y)
        # Jumps: necessary if they crossed void, climbed or cleared a hammer.
        if self.in_jump.any():
            self.jump_needed |= self.in_jump & ((floor < VOID / 2) | self.hammers.inside(pos))
            land = self.in_jump & self.grounded & (t1 - self.jump_t0 > 0.1)
            if land.any():
                needed = self.jump_needed | (pos[:, 2] > self.jump_z0 + 0.3)
                self.useless_jumps += land & ~needed
                self.in_jump &= ~land
        # Zones.
        goal_before = self.next_goal.copy()
        self._zones(pos, feet, terms)
        # Shaping towards the goal that was next at the start of the step.
        d = np.linalg.norm(self.goal_pos[goal_before] - pos, axis=1)
        terms[3] = np.where(act, np.exp(-DECAY * d) - self.potential, 0.0)
        self.potential = np.exp(-DECAY * self._goal_dist(pos))
        # Walls, staying, trapped.
        moving = (np.abs(move).sum(1) > 0) & self.grounded & (t1 >= self.knocked_until)
        if moving.any():
            ahead = pos[:, :2] + 0.5 * move
            wall_h = self.grids.floor_height(ahead[:, 0], ahead[:, 1])
            rel_v = self.vel[:, :2] - self.belt[self.support]
            slow = (rel_v * move).sum(1) < 0.3 * speed
            pressing = moving & slow & (wall_h > feet + 0.35)
        else:
            pressing = np.zeros(n, bool)
        self.wall = np.where(pressing & act, self.wall + 1, 0)
        bump = self.wall >= WALL_STEPS
        terms[4, bump] += REWARDS["fall_or_wall"]
        self.wall[bump] = 0
        away = np.hypot(*(pos[:, :2] - self.anchor).T) > STAY_DIST
        self.anchor[away] = pos[away, :2]
        self.anchor_t[away] = t1
        terms[5] = np.where(act & (t1 - self.anchor_t > STAY_S), REWARDS["stay"], 0.0)
        better = x > self.best_x + 0.5
        self.best_x[better] = x[better]
        self.best_t[better] = t1
        self.trapped |= act & ~self.success & (t1 - self.best_t > TRAPPED_S)
        terms[6] = np.where(act, REWARDS["time"], 0.0)
        cliff = self.grids.cliff_distance(x, y)
        g = self.grounded & act
        self.cliff_sum += np.where(g, cliff, 0.0)
        self.cliff_cnt += g
        # Props.
        if self.course.props:
            props = np.asarray(self.course.props)
            near = (((pos[:, None, :] - props[None]) ** 2).sum(-1) < 1.0).any(1)
            self.prop |= near & act
        total = terms.sum(0)
        self.total_reward += total
        self.goal_reward += terms[:3].sum(0)
        self.length += act
        done = act & self.success
        self.active = act & ~self.success
        return self.observe(floor), terms, done, None

    def _zones(self, pos: np.ndarray, feet: np.ndarray, terms: np.ndarray) -> None:
        act = self.active
        xy = pos[:, None, :2]
        zf = feet[:, None]
        if self.arch_lo.shape[0]:
            inside = ((xy >= self.arch_lo[:, :2]) & (xy <= self.arch_hi[:, :2])).all(-1)
            inside &= (zf > self.arch_lo[:, 2]) & (zf < self.arch_hi[:, 2]) & act[:, None]
            new = inside & ~self.arch_reached
            if new.any():
                for i, k in zip(*np.nonzero(new), strict=True):
                    self.grids.mark_reached(int(i), "archive", int(k))
                    self.last_archive[i] = k
                self.arch_reached |= new
                terms[0] += new.sum(1) * REWARDS["arrive_target"]
        if self.goal_lo.shape[0]:
            inside = ((xy >= self.goal_lo[:, :2]) & (xy <= self.goal_hi[:, :2])).all(-1)
            inside &= (zf > self.goal_lo[:, 2]) & (zf < self.goal_hi[:, 2]) & act[:, None]
            new = inside & ~self.goal_reached
            if new.any():
                for i, k in zip(*np.nonzero(new), strict=True):
                    self.grids.mark_reached(int(i), "goal", int(k))
                self.goal_reached |= new
                terms[1] += new.sum(1) * REWARDS["arrive_goal"]
                reached_all = self.goal_reached.all(1)
                first = np.argmin(self.goal_reached, axis=1)
                self.next_goal = np.where(reached_all, self.goal_reached.shape[1], first)
        local = (pos[:, :2] - self.dest[:2]) @ self.dest_rot.T
        arrive = (np.abs(local) <= self.dest_half).all(1) & (np.abs(feet - self.dest[2]) < 1.0) & act
        if arrive.any():
            for i in np.flatnonzero(arrive):
                self.grids.mark_reached(int(i), "goal", len(self.course.goals))
            self.success |= arrive
            terms[2] += arrive * REWARDS["arrive_destination"]

    def _respawn(self, idx: np.ndarray, t: float) -> None:
        spot = self.arch_pos[self.last_archive[idx]] + self.offsets[idx] * 0.5 + np.array([0, 0, 0.05])
        self.data.qpos[self.qpos_i[idx]] = spot
        self.data.qvel[self.qvel_i[idx]] = 0.0
        self.knocked_until[idx] = 0.0
        self.dash_until[idx] = 0.0
        self.launched[idx] = False
        self.grounded[idx] = False
        self.in_jump[idx] = False
        self.anchor[idx] = spot[:, :2]
        self.anchor_t[idx] = t
        mujoco.mj_kinematics(self.model, self.data)

    # --- observation ---------------------------------------------------------------------
    def observe(self, floor: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Batched observations: dict of (N, ...) float32 arrays (see ``game_env.spaces``)."""
        pos, vel = self.pos, self.vel
        x, y, z = pos[:, 0], pos[:, 1], pos[:, 2]
        feet = z - FEET
        if floor is None:
            floor = self.grids.floor_height(x, y)
        terrain, items, targets, goals = self.grids.observe(x, y, feet)
        t = self.data.time
        ag = np.empty((self.n, 32), np.float32)
        ag[:, 0] = x * self.inv_len - 1.0
        ag[:, 1:3] = pos[:, 1:] * 0.1
        ag[:, 3] = np.sin(self.yaw)
        ag[:, 4] = np.cos(self.yaw)
        ag[:, 5:8] = vel * 0.1
        g = self.grounded
        ag[:, 8] = g
        ag[:, 9] = ~g & (vel[:, 2] > 0)
        ag[:, 10] = ~g & (vel[:, 2] <= 0)
        ag[:, 11] = t < self.knocked_until
        belt = self.belt[self.support]
        ag[:, 12] = g & (np.abs(belt).sum(1) > 0)
        ag[:, 13] = self.tramps.on_pad(pos)[0] if self.tramps.n else 0.0
        ag[:, 14] = (self.tiles.geom2tile[self.support] >= 0) if self.tiles.n else 0.0
        ag[:, 15] = self.sprint
        ag[:, 16:18] = belt * 0.2
        ag[:, 18:21] = (self.arch_pos[self.last_archive] - pos) * 0.05
        gp = self.goal_pos[self.next_goal] - pos
        ag[:, 21:24] = gp * 0.05
        ag[:, 24] = np.sqrt((gp * gp).sum(1)) * 0.02
        ag[:, 25] = np.where(floor < VOID / 2, 1.0, (feet - floor) * 0.2)
        ag[:, 26] = self.grids.cliff_distance(x, y) * 0.2
        ag[:, 27] = self.next_goal / (self.goal_pos.shape[0] - 1) if self.goal_pos.shape[0] > 1 else 0.0
        ag[:, 28] = self.steps / self.max_episode_steps
        ag[:, 29] = self.prop
        ag[:, 30] = np.maximum(self.ready_t - t, 0.0) * (1.0 / COOLDOWN)
        ag[:, 31] = (t - self.anchor_t) * (1.0 / STAY_S)
        np.clip(ag, -1.0, 1.0, out=ag)
        dest = np.tile(self.dest_vec, (self.n, 1))
        dest[:, :3] = np.clip((self.dest - pos) * 0.01, -1.0, 1.0)
        return {"terrain": terrain, "items": items, "targets": targets, "goals": goals, "agent": ag,
                "destination": dest}

    def episode_metrics(self, i: int) -> dict[str, float]:
        """Per-episode metrics of racer ``i`` (the paper's table)."""
        jumps = int(self.jumps[i])
        return {
            "success": float(self.success[i]),
            "trapped": float(self.trapped[i] and not self.success[i]),
            "unnecessary_jumps": float(self.useless_jumps[i]),
            "jumps": float(jumps),
            "unnecessary_jump_rate": float(self.useless_jumps[i] / jumps) if jumps else 0.0,
            "distance_from_cliff": float(self.cliff_sum[i] / self.cliff_cnt[i]) if self.cliff_cnt[i] else 0.0,
            "goal_reward": float(self.goal_reward[i]),
            "total_reward": float(self.total_reward[i]),
            "episode_length": float(self.length[i]),
        }


def _zone_boxes(zones) -> tuple[np.ndarray, np.ndarray]:
    """(K, 3) lower/upper corners of zone regions: footprint, feet from z-0.5 to z+2.5."""
    lo = np.array([[z.cx - z.hx, z.cy - z.hy, z.z - 0.5] for z in zones]).reshape(-1, 3)
    hi = np.array([[z.cx + z.hx, z.cy + z.hy, z.z + 2.5] for z in zones]).reshape(-1, 3)
    return lo, hi
