"""The race simulator: N racers in one MuJoCo scene, controls, rules and observations.

``RaceSim`` is shared by the Gymnasium env (N = 1) and the PettingZoo env (N racers); it knows
neither API: ``step`` takes an (N, 8) int action array. Speed notes: per-racer rules are plain
float math (numpy on 1-8 element arrays costs more than it saves); everything grid-shaped is
batched across racers with numpy; contacts are read once per env step, and only where they
matter (several racers, balloons); floors, belts and tiles are looked up in the course maps.
"""

from __future__ import annotations

import math
import operator

import mujoco
import numpy as np

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
    RACER_RADIUS,
    RUN_SPEED,
    SPRINT_SPEED,
)
from game_env.grids import FINE, VOID, CourseGrids, _clip
from game_env.mechanics import DECEL, Balloons, Hammers, Tiles, Trampolines, knock_speed
from game_env.scene import load_scene, spawn_offsets
from game_env.spaces import AGENT_FEATURES, DESTINATION_FEATURES, REWARD_TERMS

STAY_S = 2.0  # stationary this long (moved < STAY_DIST) -> stay penalty
STAY_DIST = 0.5
TRAPPED_S = 10.0  # no new best progress this long -> trapped
WALL_STEPS = 25  # env steps pressing into a wall -> wall penalty
DECAY = 0.05  # goal-distance shaping: potential exp(-DECAY * distance)
R_TARGET, R_GOAL, R_DEST, R_FALL, R_STAY, R_TIME = 1.0, 0.3, 1.0, -1.0, -0.01, -0.02
_bad_warnings = operator.itemgetter(int(mujoco.mjtWarning.mjWARN_BADQPOS), int(mujoco.mjtWarning.mjWARN_BADQVEL),
                                    int(mujoco.mjtWarning.mjWARN_BADQACC))
_DIRS = [(math.cos(k * math.pi / 4), math.sin(k * math.pi / 4)) for k in range(8)]
_S2 = math.sqrt(0.5)
_agent_vector = operator.itemgetter(*AGENT_FEATURES)  # named features -> the vector's order
_destination_vector = operator.itemgetter(*DESTINATION_FEATURES)
assert DESTINATION_FEATURES[:3] == ("dx", "dy", "dz")  # the moving part; the rest is fixed per course


class Racer:
    """Per-racer state (plain Python floats for speed)."""

    __slots__ = (
        "active", "success", "yaw", "grounded", "belt", "launched", "carry", "knock_t0", "knock_until",
        "knock_v0", "knock_dir", "dash_until", "dash_vel", "ready_t", "prop", "sprint", "last_archive",
        "arch_reached", "goal_reached", "next_goal", "anchor", "anchor_t", "best_x", "best_t", "wall",
        "in_jump", "jump_z0", "jump_t0", "jump_needed", "jumps", "useless_jumps", "trapped",
        "cliff_sum", "cliff_cnt", "goal_reward", "total_reward", "length", "potential", "on_tile",
        "on_pad", "move", "speed",
    )

    def __init__(self, n_arch: int, n_goals: int, x: float, y: float) -> None:
        self.active, self.success, self.yaw, self.grounded = True, False, 0.0, True
        self.belt, self.launched, self.carry = (0.0, 0.0), False, (0.0, 0.0)
        self.knock_t0 = self.knock_until = self.knock_v0 = 0.0
        self.knock_dir = (0.0, 0.0)
        self.dash_until, self.dash_vel, self.ready_t = 0.0, (0.0, 0.0), 0.0
        self.prop = self.sprint = False
        self.last_archive = n_arch  # index into arch_pos: n_arch = the start
        self.arch_reached = [False] * n_arch
        self.goal_reached = [False] * n_goals
        self.next_goal = 0
        self.anchor, self.anchor_t, self.best_x, self.best_t = (x, y), 0.0, x, 0.0
        self.wall, self.in_jump, self.jump_z0, self.jump_t0, self.jump_needed = 0, False, 0.0, 0.0, False
        self.jumps = self.useless_jumps = 0
        self.trapped = False
        self.cliff_sum = self.goal_reward = self.total_reward = 0.0
        self.cliff_cnt = self.length = 0
        self.potential = 0.0
        self.on_tile = self.on_pad = False
        self.move, self.speed = (0.0, 0.0), RUN_SPEED


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
        self.warnings = self.data.warning.number  # a live view
        self.half_step = 0.5 * self.frame_skip * model.opt.timestep  # s
        self.grids = g = CourseGrids(course, self.n)
        self.hammers = Hammers(course, idx)
        self.tramps = Trampolines(course)
        self.tiles = Tiles(course, idx, g)
        self.balloons = Balloons(course, model, idx)
        self.need_contacts = bool(self.balloons.burstable.any())  # touches burst balloons
        self.geom2racer = np.full(model.ngeom + 1, -1, np.intp)
        self.geom2racer[idx.racer_geom] = np.arange(self.n)
        self.qpos_i = idx.racer_qpos
        self.qvel_i = idx.racer_qvel
        self.qpos_flat = _as_slice(idx.racer_qpos.ravel())  # racers' x, y, z (contiguous: a slice)
        self.qvel_flat = _as_slice(idx.racer_qvel.ravel())
        self.vz_adr = [int(a) for a in idx.racer_qvel[:, 2]]
        self.vxy_adr = [(int(a), int(b)) for a, b in idx.racer_qvel[:, :2]]
        self.ctrl_i = idx.racer_ctrl.ravel()
        self.offsets = spawn_offsets(self.n).tolist()
        c = course
        self.archives = [(z.cx - z.hx, z.cx + z.hx, z.cy - z.hy, z.cy + z.hy, z.z) for z in c.archives]
        self.goals = [(z.cx - z.hx, z.cx + z.hx, z.cy - z.hy, z.cy + z.hy, z.z) for z in c.goals]
        d = c.destination
        self.dest = (d.cx, d.cy, d.z, math.cos(d.yaw), math.sin(d.yaw), d.hx, d.hy)
        self.goal_pos = [(z.cx, z.cy, z.z + FEET) for z in [*c.goals, d]]
        self.arch_pos = [(z.cx, z.cy, z.z + FEET) for z in c.archives] + [(c.start[0], c.start[1], c.start[2] + FEET)]
        self.fall_z = c.floor_min - FALL_DEPTH
        self.inv_len = 2.0 / c.length
        dest_static = {"yaw_sin": math.sin(d.yaw), "yaw_cos": math.cos(d.yaw), "tilt": 0.0,
                       "size_x": d.hx / 10, "size_y": d.hy / 10, "size_z": 0.003}
        self.dest_tail = _destination_vector({"dx": 0.0, "dy": 0.0, "dz": 0.0, **dest_static})[3:]
        self.props = list(c.props)
        self.maps = (g.fine_h, g.belt_x, g.belt_y, g.tile_id, g.cliff)
        self.fine = (g.x_min, g.y_min, 1.0 / FINE, g.nx - 1, g.ny - 1)

    # --- episode -----------------------------------------------------------------------
    def reset(self) -> dict[str, np.ndarray]:
        """Racers back on the start pad, hazards back to their initial state."""
        mujoco.mj_resetData(self.model, self.data)
        self.tiles.reset()
        self.grids.reset_tiles()
        self.grids.reset_zones()
        self.balloons.reset()
        self.hammers.pose(self.data, 0.0)
        mujoco.mj_forward(self.model, self.data)
        self.steps = 0
        pos = self.data.qpos[self.qpos_flat].tolist()
        c = self.course
        self.racers = [Racer(len(c.archives), len(c.goals), pos[3 * i], pos[3 * i + 1]) for i in range(self.n)]
        for i, r in enumerate(self.racers):
            gx, gy, gz = self.goal_pos[0]
            r.potential = math.exp(-DECAY * math.dist((gx, gy, gz), pos[3 * i: 3 * i + 3]))
        self._warn = self._bad_count()
        self.last_pos = pos
        self._agent_rows = [None] * self.n
        return self._observe(pos, self.data.qvel[self.qvel_flat].tolist(), [self._floor(pos, i)[0] for i in range(self.n)])

    def sync_visuals(self) -> None:
        """Turn the hammer bars (visual only; hits are computed from their phase) to now."""
        self.hammers.pose(self.data, self.data.time)

    @property
    def pos(self) -> np.ndarray:
        """(N, 3) racer centre positions."""
        return self.data.qpos[self.qpos_i]

    @property
    def vel(self) -> np.ndarray:
        return self.data.qvel[self.qvel_i]

    @property
    def success(self) -> np.ndarray:
        return np.array([r.success for r in self.racers])

    def _bad_count(self) -> int:
        return sum(_bad_warnings(self.warnings.tolist()))

    def _floor(self, pos: list[float], i: int) -> tuple[float, int, int]:
        x0, y0, inv, mx, my = self.fine
        ix = min(max(int((pos[3 * i] - x0) * inv), 0), mx)
        iy = min(max(int((pos[3 * i + 1] - y0) * inv), 0), my)
        return float(self.maps[0][ix, iy]), ix, iy

    # --- one env step ------------------------------------------------------------------
    def step(self, actions) -> tuple[dict[str, np.ndarray], list[dict[str, float]], list[bool], str | None]:
        """Advance one env step with (N, 8) actions (array or list of lists of valid ints).

        Returns (batched obs, reward terms per racer (N fresh dicts keyed by
        ``spaces.REWARD_TERMS``, in that order; the step reward is their sum), done per racer
        (reached the destination this step), physics error message or None). Time limits are
        the caller's (``self.steps``).
        """
        data = self.data
        t0 = data.time
        half = self.half_step
        ctrl = []
        if isinstance(actions, np.ndarray):
            actions = actions.tolist()
        for i, (r, a) in enumerate(zip(self.racers, actions, strict=True)):
            ctrl += self._control(i, r, a, t0, half) if r.active else (0.0, 0.0)
        data.ctrl[:] = ctrl  # actuators are (racer0 x, racer0 y, racer1 x, ...)
        mujoco.mj_step(self.model, data, nstep=self.frame_skip)
        self.steps += 1
        if self._bad_count() != self._warn:
            self._warn = self._bad_count()
            pos = data.qpos[self.qpos_flat].tolist()
            return (self._observe(pos, [0.0] * (3 * self.n), [VOID] * self.n),
                    [dict.fromkeys(REWARD_TERMS, 0.0) for _ in self.racers],
                    [False] * self.n, f"MuJoCo physics became unstable at t={data.time:.3f}s (bad qpos/qvel/qacc)")
        return self._after_physics(t0, data.time)

    def _control(self, i: int, r: Racer, a: list[int], t0: float, half: float) -> tuple[float, float]:
        """Apply active racer ``i``'s action ``a`` at time ``t0`` (move, sprint, dash, jump,
        attack); returns its horizontal velocity target for the step (``half``: half a step,
        in s)."""
        mx, my = (0, 0) if a[7] else (a[0] - 1, a[1] - 1)
        if mx or my:
            s = _S2 if mx and my else 1.0
            dx, dy = mx * s, my * s
            r.yaw = math.atan2(my, mx)
            r.sprint = a[3] == 1
        else:
            dx = dy = 0.0
            r.sprint = False
        spd = SPRINT_SPEED if r.sprint else RUN_SPEED
        r.move, r.speed = (dx, dy), spd
        knocked = t0 < r.knock_until
        ready = t0 >= r.ready_t and not knocked
        if ready and a[5] and r.prop:
            ux, uy = _DIRS[a[6]]
            r.dash_vel, r.dash_until, r.prop, r.ready_t = (DASH_SPEED * ux, DASH_SPEED * uy), t0 + DASH_TIME, False, t0 + COOLDOWN
        if knocked:  # slide with emulated friction (the racer's contacts are frictionless)
            v = max(r.knock_v0 - DECEL * (t0 + half - r.knock_t0), 0.0)
            tx, ty = r.knock_dir[0] * v, r.knock_dir[1] * v
        elif t0 < r.dash_until:
            tx, ty = r.dash_vel
        else:
            bx, by = r.belt if r.grounded else (r.carry if r.launched else (0.0, 0.0))
            tx, ty = bx + dx * spd, by + dy * spd
        if ready and a[2] and r.grounded:
            self.data.qvel[self.vz_adr[i]] = JUMP_SPEED
            r.grounded, r.ready_t, r.in_jump, r.jump_needed = False, t0 + COOLDOWN, True, False
            r.jumps += 1
            r.jump_z0, r.jump_t0 = self.last_pos[3 * i + 2], t0
        if ready and a[4] and self.n > 1:
            self._attack(i, t0)
        return tx, ty

    def _attack(self, i: int, t: float) -> None:
        pos = self.last_pos
        xi, yi = pos[3 * i], pos[3 * i + 1]
        for j, other in enumerate(self.racers):
            if j == i or not other.active:
                continue
            dx, dy = pos[3 * j] - xi, pos[3 * j + 1] - yi
            dist = math.hypot(dx, dy)
            if 1e-6 < dist < ATTACK_RANGE:
                self.knock(j, dx / dist, dy / dist, ATTACK_KNOCK, t)
        self.racers[i].ready_t = t + COOLDOWN

    def knock(self, i: int, dx: float, dy: float, distance: float, t: float) -> None:
        """Knock racer ``i`` back along unit (dx, dy) so that it slides ``distance`` m."""
        r = self.racers[i]
        v0 = knock_speed(distance)
        r.knock_t0, r.knock_v0, r.knock_dir = t, v0, (dx, dy)
        r.knock_until = t + v0 / DECEL + 0.05
        r.dash_until, r.launched = 0.0, False
        ax, ay = self.vxy_adr[i]
        self.data.qvel[ax], self.data.qvel[ay] = v0 * dx, v0 * dy

    def _touched(self) -> np.ndarray:
        """Read contacts once: the geoms any racer touches."""
        data = self.data
        nc = data.ncon
        if not nc:
            return np.zeros(0, np.intp)
        g = data.contact.geom[:nc]
        r0, r1 = self.geom2racer[g[:, 0]] >= 0, self.geom2racer[g[:, 1]] >= 0
        return np.concatenate((g[r0, 1], g[r1, 0]))

    def _on_racer(self, pos: list[float], i: int) -> bool:
        """Whether racer ``i`` stands on another racer's head (capsules stacked)."""
        reach, top = (2 * RACER_RADIUS) ** 2, 2 * FEET
        xi, yi, zi = pos[3 * i: 3 * i + 3]
        for j in range(self.n):
            if j != i:
                dz = zi - pos[3 * j + 2]
                if top - 0.45 < dz < top + 0.1 and (xi - pos[3 * j]) ** 2 + (yi - pos[3 * j + 1]) ** 2 < reach:
                    return True
        return False

    # --- the rules, after the physics step --------------------------------------------------
    def _after_physics(self, t0: float, t1: float):
        """Apply the race rules to every racer for the step (t0, t1]; returns ``step``'s tuple."""
        pos = self.data.qpos[self.qpos_flat].tolist()
        vel = self.data.qvel[self.qvel_flat].tolist()
        if self.need_contacts:
            self.balloons.touch(self._touched())
        cliff_map = self.maps[4]
        all_terms, done, floors, cliffs = [], [], [], []
        for i, r in enumerate(self.racers):
            terms = dict.fromkeys(REWARD_TERMS, 0.0)
            all_terms.append(terms)
            if r.active:
                floor, cliff = self._racer_rules(i, r, pos, vel, t0, t1, terms)
                done.append(r.success)
                r.active = not r.success  # a racer that arrived leaves the race
            else:
                floor, ix, iy = self._floor(pos, i)
                cliff = float(cliff_map[ix, iy])
                done.append(False)
            floors.append(floor)
            cliffs.append(cliff)
        self.tiles.update(self.data, t1)
        self.last_pos = pos
        return self._observe(pos, vel, floors, cliffs), all_terms, done, None

    def _racer_rules(self, i: int, r: Racer, pos: list[float], vel: list[float], t0: float, t1: float,
                     terms: dict[str, float]) -> tuple[float, float]:
        """The rules for active racer ``i``, in order; ``pos`` is updated on a respawn.
        Returns the floor height and the cliff distance under the racer."""
        grounded, floor, ix, iy = self._land(i, r, pos, vel[3 * i + 2], t1)
        x, y, z = pos[3 * i: 3 * i + 3]
        if self.hammers.n and t1 >= r.knock_until:
            self._hammer_hit(i, x, y, z - FEET, t0, t1)
        if z < self.fall_z:  # fell: respawn at the last archive point
            terms["fall_or_wall"] += R_FALL
            x, y, z = self._respawn(i, t1)
            pos[3 * i: 3 * i + 3] = (x, y, z)
            floor, ix, iy = self._floor(pos, i)
        feet = z - FEET
        cliff = float(self.maps[4][ix, iy])
        if r.in_jump:
            self._track_jump(r, x, y, z, floor, grounded, t1)
        goal_before = r.next_goal
        self._zones(r, i, x, y, feet, terms)
        self._goal_distance_shaping(r, x, y, z, goal_before, terms)
        self._wall(r, i, x, y, feet, vel, grounded, t1, terms)
        self._stay_and_progress(r, x, y, t1, terms)
        terms["time"] = R_TIME
        if self.props and not r.prop:
            r.prop = any((x - px) ** 2 + (y - py) ** 2 + (z - pz) ** 2 < 1.0 for px, py, pz in self.props)
        self._account(r, grounded, cliff, terms)
        return floor, cliff

    def _land(self, i: int, r: Racer, pos: list[float], vz: float, t1: float) -> tuple[bool, float, int, int]:
        """Ground contact of racer ``i``: standing (on the floor or another racer's head), the
        belt under its feet, a touched tile, a trampoline launch. Returns (grounded after a
        launch, floor height, fine-grid cell)."""
        x, y, z = pos[3 * i: 3 * i + 3]
        floor, ix, iy = self._floor(pos, i)
        feet = z - FEET
        near = feet - floor < 0.06 and abs(vz) < 1.5
        grounded = near or (self.n > 1 and vz < 1.0 and self._on_racer(pos, i))
        r.grounded = grounded
        r.on_pad = r.on_tile = False
        if grounded:
            r.launched = False
            _, belt_x, belt_y, tile_id, _ = self.maps
            r.belt = (float(belt_x[ix, iy]), float(belt_y[ix, iy])) if near else (0.0, 0.0)
            k = int(tile_id[ix, iy]) if near else -1
            if k >= 0:
                r.on_tile = True
                self.tiles.touch(k, t1)
            if self.tramps.n and vz < 0.5:
                p = self.tramps.pad(x, y, feet)
                if p >= 0:  # launch along the pad normal
                    vx_l, vz_l = self.tramps.vel[p]
                    qvel = self.data.qvel
                    qvel[self.vz_adr[i]] = vz_l
                    qvel[self.vxy_adr[i][0]] = vx_l
                    r.carry, r.launched, r.grounded, r.on_pad = (vx_l, 0.0), True, False, True
                    r.jump_needed = True
                    grounded = False
        return grounded, floor, ix, iy

    def _hammer_hit(self, i: int, x: float, y: float, feet: float, t0: float, t1: float) -> None:
        """Knock racer ``i`` back if a hammer bar swept through it during (t0, t1]."""
        hit = self.hammers.hit(x, y, feet, t0, t1)
        if hit is not None:
            self.knock(i, hit[0], hit[1], hit[2], t1)

    def _track_jump(self, r: Racer, x: float, y: float, z: float, floor: float, grounded: bool,
                    t1: float) -> None:
        """A jump is necessary if it crosses void, climbs or clears a hammer; on landing an
        unnecessary one is counted (episode metric ``unnecessary_jumps``)."""
        if floor < VOID / 2 or (self.hammers.n and self.hammers.near(x, y)):
            r.jump_needed = True
        if grounded and t1 - r.jump_t0 > 0.1:
            if not (r.jump_needed or z > r.jump_z0 + 0.3):
                r.useless_jumps += 1
            r.in_jump = False

    def _zones(self, r: Racer, i: int, x: float, y: float, feet: float, terms: dict[str, float]) -> None:
        """Archive points, intermediate goals and the destination reached this step."""
        for k, (x0, x1, y0, y1, zz) in enumerate(self.archives):
            if x0 <= x <= x1 and y0 <= y <= y1 and zz - 0.5 < feet < zz + 2.5 and not r.arch_reached[k]:
                r.arch_reached[k] = True
                r.last_archive = k
                terms["arrive_target"] += R_TARGET
                self.grids.mark_reached(i, "archive", k)
        for k, (x0, x1, y0, y1, zz) in enumerate(self.goals):
            if x0 <= x <= x1 and y0 <= y <= y1 and zz - 0.5 < feet < zz + 2.5 and not r.goal_reached[k]:
                r.goal_reached[k] = True
                terms["arrive_goal"] += R_GOAL
                self.grids.mark_reached(i, "goal", k)
                r.next_goal = next((j for j, done in enumerate(r.goal_reached) if not done), len(self.goals))
        cx, cy, cz, c, s, hx, hy = self.dest
        lx, ly = (x - cx) * c + (y - cy) * s, -(x - cx) * s + (y - cy) * c
        if abs(lx) <= hx and abs(ly) <= hy and abs(feet - cz) < 1.0:
            r.success = True
            terms["arrive_destination"] += R_DEST
            self.grids.mark_reached(i, "goal", len(self.goals))

    def _goal_distance_shaping(self, r: Racer, x: float, y: float, z: float, goal_before: int,
                               terms: dict[str, float]) -> None:
        """Potential-based shaping: change of exp(-DECAY * distance) to the goal the racer was
        heading for; the potential then moves on to the next goal."""
        gx, gy, gz = self.goal_pos[goal_before]
        phi = math.exp(-DECAY * math.sqrt((gx - x) ** 2 + (gy - y) ** 2 + (gz - z) ** 2))
        terms["goal_distance"] = phi - r.potential
        if r.next_goal != goal_before:
            gx, gy, gz = self.goal_pos[r.next_goal]
            phi = math.exp(-DECAY * math.sqrt((gx - x) ** 2 + (gy - y) ** 2 + (gz - z) ** 2))
        r.potential = phi

    def _wall(self, r: Racer, i: int, x: float, y: float, feet: float, vel: list[float], grounded: bool,
              t1: float, terms: dict[str, float]) -> None:
        """Pressing into a wall (a ledge higher than a step just ahead, no progress) for
        ``WALL_STEPS`` steps costs the fall penalty."""
        dx, dy = r.move
        if grounded and (dx or dy) and t1 >= r.knock_until:
            ahead = self._floor([x + 0.5 * dx, y + 0.5 * dy, 0.0], 0)[0]
            vrel = (vel[3 * i] - r.belt[0]) * dx + (vel[3 * i + 1] - r.belt[1]) * dy
            r.wall = r.wall + 1 if ahead > feet + 0.35 and vrel < 0.3 * r.speed else 0
            if r.wall >= WALL_STEPS:
                terms["fall_or_wall"] += R_FALL
                r.wall = 0
        else:
            r.wall = 0

    def _stay_and_progress(self, r: Racer, x: float, y: float, t1: float, terms: dict[str, float]) -> None:
        """Stay penalty after ``STAY_S`` within ``STAY_DIST``; trapped after ``TRAPPED_S``
        without new best progress."""
        if math.hypot(x - r.anchor[0], y - r.anchor[1]) > STAY_DIST:
            r.anchor, r.anchor_t = (x, y), t1
        if t1 - r.anchor_t > STAY_S:
            terms["stay"] = R_STAY
        if x > r.best_x + 0.5:
            r.best_x, r.best_t = x, t1
        if not r.success and t1 - r.best_t > TRAPPED_S:
            r.trapped = True

    @staticmethod
    def _account(r: Racer, grounded: bool, cliff: float, terms: dict[str, float]) -> None:
        """Running episode metrics: cliff distance while grounded, rewards, length."""
        if grounded:
            r.cliff_sum += cliff
            r.cliff_cnt += 1
        r.total_reward += sum(terms.values())
        r.goal_reward += terms["arrive_target"] + terms["arrive_goal"] + terms["arrive_destination"]
        r.length += 1

    def _respawn(self, i: int, t: float) -> tuple[float, float, float]:
        r = self.racers[i]
        ax, ay, az = self.arch_pos[r.last_archive]
        ox, oy = self.offsets[i]
        spot = (ax + 0.5 * ox, ay + 0.5 * oy, az + 0.05)
        self.data.qpos[self.qpos_i[i]] = spot
        self.data.qvel[self.qvel_i[i]] = 0.0
        r.knock_until = r.dash_until = 0.0
        r.launched = r.grounded = r.in_jump = False
        r.anchor, r.anchor_t = spot[:2], t
        return spot

    # --- observation ---------------------------------------------------------------------
    def _observe(self, pos: list[float], vel: list[float], floors: list[float],
                 cliffs: list[float] | None = None) -> dict[str, np.ndarray]:
        """Batched observations: dict of (N, ...) float32 arrays (see ``game_env.spaces``)."""
        t = self.data.time
        tf = self.steps / self.max_episode_steps
        ng = len(self.goal_pos) - 1
        cx, cy, cz = self.dest[:3]
        rows, feet5 = [], []
        for i, r in enumerate(self.racers):
            x, y, z = pos[3 * i: 3 * i + 3]
            vx, vy, vz = vel[3 * i: 3 * i + 3]
            g = r.grounded
            ax, ay, az = self.arch_pos[r.last_archive]
            gx, gy, gz = self.goal_pos[r.next_goal]
            gx, gy, gz = gx - x, gy - y, gz - z
            feet = z - FEET
            feet5.append(feet * 0.2)
            fl = floors[i]
            agent = {
                "progress_x": x * self.inv_len - 1.0,
                "pos_y": y * 0.1,
                "pos_z": z * 0.1,
                "yaw_sin": math.sin(r.yaw),
                "yaw_cos": math.cos(r.yaw),
                "vel_x": vx * 0.1,
                "vel_y": vy * 0.1,
                "vel_z": vz * 0.1,
                "grounded": g,
                "jumping": not g and vz > 0,
                "falling": not g and vz <= 0,
                "knocked": t < r.knock_until,
                "on_conveyor": g and (r.belt[0] != 0.0 or r.belt[1] != 0.0),
                "on_trampoline": r.on_pad,
                "on_collapsing": r.on_tile,
                "sprinting": r.sprint,
                "belt_vel_x": r.belt[0] * 0.2,
                "belt_vel_y": r.belt[1] * 0.2,
                "archive_dx": (ax - x) * 0.05,
                "archive_dy": (ay - y) * 0.05,
                "archive_dz": (az - z) * 0.05,
                "next_goal_dx": gx * 0.05,
                "next_goal_dy": gy * 0.05,
                "next_goal_dz": gz * 0.05,
                "next_goal_dist": math.sqrt(gx * gx + gy * gy + gz * gz) * 0.02,
                "height_above_floor": 1.0 if fl < VOID / 2 else (feet - fl) * 0.2,
                "distance_from_cliff": (cliffs[i] if cliffs is not None else self._cliff(pos, i)) * 0.2,
                "goals_fraction": r.next_goal / ng if ng else 0.0,
                "time_fraction": tf,
                "prop_held": r.prop,
                "cooldown": max(r.ready_t - t, 0.0) / COOLDOWN,
                "stay_fraction": (t - r.anchor_t) / STAY_S,
            }
            dest = ((cx - x) * 0.01, (cy - y) * 0.01, (cz - feet) * 0.01)  # dx, dy, dz
            rows.append(_agent_vector(agent) + dest + self.dest_tail)
        grid = self.grids.observe_all(np.array(pos).reshape(self.n, 3)[:, :2], np.array(feet5))
        vec = np.array(rows, np.float32)
        _clip(vec, -1.0, 1.0, out=vec)
        na = len(AGENT_FEATURES)
        return {"terrain": grid[:, 0:4], "items": grid[:, 4:6], "targets": grid[:, 6:9], "goals": grid[:, 9:12],
                "agent": vec[:, :na], "destination": vec[:, na:]}

    def _cliff(self, pos: list[float], i: int) -> float:
        _, ix, iy = self._floor(pos, i)
        return float(self.maps[4][ix, iy])

    def episode_metrics(self, i: int) -> dict[str, float]:
        """Per-episode metrics of racer ``i`` (the paper's table)."""
        r = self.racers[i]
        return {
            "success": float(r.success),
            "trapped": float(r.trapped and not r.success),
            "unnecessary_jumps": float(r.useless_jumps),
            "jumps": float(r.jumps),
            "unnecessary_jump_rate": r.useless_jumps / r.jumps if r.jumps else 0.0,
            "distance_from_cliff": r.cliff_sum / r.cliff_cnt if r.cliff_cnt else 0.0,
            "goal_reward": r.goal_reward,
            "total_reward": r.total_reward,
            "episode_length": float(r.length),
        }


def _as_slice(idx: np.ndarray) -> slice | np.ndarray:
    """A slice when ``idx`` is a contiguous ascending run (cheaper to index with)."""
    if idx.size and (np.diff(idx) == 1).all():
        return slice(int(idx[0]), int(idx[-1]) + 1)
    return idx
