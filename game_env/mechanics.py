"""Course elements with state or scripted behaviour: hammers, tiles, trampolines, balloons.

Each works on all racers at once (numpy arrays of shape (N, ...)) and is called once per env
step, after the physics substeps.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from game_env.constants import FEET, FRICTION, GRAVITY, RACER_RADIUS
from game_env.course import Course
from game_env.grids import CourseGrids
from game_env.scene import SceneIndex


def knock_speed(distance: float | np.ndarray) -> float | np.ndarray:
    """Initial sliding speed that stops after ``distance`` m under friction: sqrt(2 mu g D)."""
    return np.sqrt(2.0 * FRICTION * GRAVITY * np.asarray(distance))


def knock_duration(distance: float | np.ndarray) -> float | np.ndarray:
    """Time (s) the slide of a knock-back over ``distance`` lasts, plus a short margin."""
    return knock_speed(distance) / (FRICTION * GRAVITY) + 0.1


class Hammers:
    """Sweeping bars rotating about a vertical post; a hit knocks a racer along the sweep."""

    def __init__(self, course: Course, index: SceneIndex) -> None:
        hs = course.hammers
        self.n = len(hs)
        self.mocap = index.hammer_mocap
        self.pivot = np.array([[h.px, h.py] for h in hs]).reshape(-1, 2)
        self.floor = np.array([h.floor for h in hs])
        self.arm = np.array([h.arm for h in hs])
        self.omega = np.array([h.omega for h in hs])
        self.phase = np.array([h.phase for h in hs])
        self.knock = np.array([h.knock for h in hs])
        self.period = np.array([2 * math.pi / h.arms for h in hs])
        self.top = np.array([h.floor + h.bar_top for h in hs])

    def angle(self, t: float) -> np.ndarray:
        """Bar angles (rad) at time ``t``."""
        return self.phase + self.omega * t

    def pose(self, data: mujoco.MjData, t: float) -> None:
        """Turn the (visual) bars to their angle at time ``t``."""
        if self.n:
            half = 0.5 * self.angle(t)
            data.mocap_quat[self.mocap, 0] = np.cos(half)
            data.mocap_quat[self.mocap, 3] = np.sin(half)

    def hits(self, pos: np.ndarray, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Racers the bars swept over during [t0, t1]: (hit (N,), direction (N, 2), distance (N,))."""
        n = pos.shape[0]
        if not self.n:
            return np.zeros(n, bool), np.zeros((n, 2)), np.zeros(n)
        rel = pos[:, None, :2] - self.pivot[None]  # (N, H, 2)
        r = np.hypot(rel[..., 0], rel[..., 1])
        phi = np.arctan2(rel[..., 1], rel[..., 0])
        sgn = np.sign(self.omega)
        hw = (0.15 + RACER_RADIUS) / np.maximum(r, 0.3)
        d = np.mod((phi - self.angle(t0) + sgn * hw) * sgn, self.period)
        swept = np.abs(self.omega) * (t1 - t0) + 2 * hw
        feet = pos[:, None, 2] - FEET
        hit = (d <= swept) & (r <= self.arm + RACER_RADIUS) & (feet < self.top) & (feet > self.floor - 0.5)
        any_hit = hit.any(axis=1)
        k = np.argmax(hit, axis=1)
        rows = np.arange(n)
        ph = phi[rows, k]
        direction = (sgn[k] * np.stack((-np.sin(ph), np.cos(ph)))).T
        return any_hit, direction, self.knock[k]

    def inside(self, pos: np.ndarray) -> np.ndarray:
        """(N,) whether each racer is within a hammer's reach (horizontally)."""
        if not self.n:
            return np.zeros(pos.shape[0], bool)
        rel = pos[:, None, :2] - self.pivot[None]
        return ((rel**2).sum(-1) <= (self.arm + RACER_RADIUS) ** 2).any(axis=1)


class Trampolines:
    """Scripted launch pads: a racer standing on a pad gets v = sqrt(2 g H) / n_z * n."""

    def __init__(self, course: Course) -> None:
        ts = course.trampolines
        self.n = len(ts)
        self.lo = np.array([[t.cx - t.hx, t.cy - t.hy] for t in ts]).reshape(-1, 2)
        self.hi = np.array([[t.cx + t.hx, t.cy + t.hy] for t in ts]).reshape(-1, 2)
        self.top = np.array([t.top for t in ts])
        self.height = np.array([t.height for t in ts])
        vz = np.sqrt(2 * GRAVITY * self.height)
        self.vel = np.array([[math.tan(t.tilt) * v, 0.0, v] for t, v in zip(ts, vz, strict=True)]).reshape(-1, 3)

    def on_pad(self, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N,) whether each racer's feet are on a pad, and which pad."""
        n = pos.shape[0]
        if not self.n:
            return np.zeros(n, bool), np.zeros(n, np.intp)
        xy = pos[:, None, :2]
        inside = ((xy >= self.lo) & (xy <= self.hi)).all(-1)
        inside &= np.abs(pos[:, None, 2] - FEET - self.top) < 0.12
        return inside.any(axis=1), np.argmax(inside, axis=1)


class Tiles:
    """Collapsing floor tiles (mocap bodies): drop ``delay`` s after first touched."""

    def __init__(self, course: Course, index: SceneIndex, grids: CourseGrids, ngeom: int) -> None:
        ts = course.tiles
        self.n = len(ts)
        self.grids = grids
        self.mocap = index.tile_mocap
        self.z0 = np.array([t.top - 0.25 for t in ts])
        self.collapses = np.array([t.collapses for t in ts], bool)
        self.delay = np.array([t.delay for t in ts])
        self.returns = np.array([t.returns for t in ts], bool)
        self.return_time = np.array([t.return_time for t in ts])
        self.geom2tile = np.full(ngeom + 1, -1, np.intp)  # index -1 (no support) -> -1
        self.geom2tile[index.tile_geom] = np.arange(self.n)
        self.reset()

    def reset(self) -> None:
        self.trigger = np.full(self.n, np.inf)
        self.drop_t = np.full(self.n, np.inf)
        self.down = np.zeros(self.n, bool)

    def update(self, data: mujoco.MjData, support: np.ndarray, t: float) -> None:
        """Start timers of touched tiles, drop, animate and return tiles (time ``t``)."""
        if not self.n:
            return
        k = self.geom2tile[support]
        k = k[k >= 0]
        if k.size:
            k = k[self.collapses[k] & np.isinf(self.trigger[k])]
            self.trigger[k] = t
        start = ~self.down & (t >= self.trigger + self.delay)
        for j in np.flatnonzero(start):
            self.down[j] = True
            self.drop_t[j] = self.trigger[j] + self.delay[j]
            self.grids.set_tile(int(j), False)
        back = self.down & self.returns & (t >= self.drop_t + self.return_time)
        for j in np.flatnonzero(back):
            self.down[j] = False
            self.trigger[j] = self.drop_t[j] = np.inf
            data.mocap_pos[self.mocap[j], 2] = self.z0[j]
            self.grids.set_tile(int(j), True)
        if self.down.any():
            j = np.flatnonzero(self.down)
            fall = np.minimum(0.5 * GRAVITY * (t - self.drop_t[j]) ** 2, 40.0)
            data.mocap_pos[self.mocap[j], 2] = self.z0[j] - fall


class Balloons:
    """Spring-mounted balloons; on maps where they burst, a touch removes them."""

    def __init__(self, course: Course, model: mujoco.MjModel, index: SceneIndex) -> None:
        bs = course.balloons
        self.n = len(bs)
        self.model = model
        self.geom = index.balloon_geom
        self.burstable = np.array([b.burst for b in bs], bool)
        self.geom2balloon = np.full(model.ngeom + 1, -1, np.intp)
        self.geom2balloon[self.geom] = np.arange(self.n)
        self.rgba = model.geom_rgba[self.geom].copy()
        self.reset()

    def reset(self) -> None:
        if self.n:
            self.burst = np.zeros(self.n, bool)
            self.model.geom_contype[self.geom] = 2
            self.model.geom_rgba[self.geom] = self.rgba

    def touch(self, geoms: np.ndarray) -> None:
        """Geoms the racers touched this step: burst the burstable balloons among them."""
        if not self.n or not geoms.size:
            return
        k = self.geom2balloon[geoms]
        k = k[k >= 0]
        k = k[self.burstable[k] & ~self.burst[k]]
        if k.size:
            self.burst[k] = True
            self.model.geom_contype[self.geom[k]] = 0
            self.model.geom_rgba[self.geom[k], 3] = 0.0
