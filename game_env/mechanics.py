"""Course elements with state or scripted behaviour: hammers, trampolines, tiles, balloons.

Hammers and trampolines answer per-racer questions with plain float math (cheaper than numpy
for a handful of elements); tiles and balloons keep their state in arrays and MjModel/MjData.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from game_env.constants import FRICTION, GRAVITY, RACER_RADIUS
from game_env.course import Course
from game_env.grids import CourseGrids
from game_env.scene import SceneIndex

DECEL = FRICTION * GRAVITY  # deceleration of a knocked racer's slide (m/s^2)


def knock_speed(distance: float) -> float:
    """Initial slide speed that stops after ``distance`` m: sqrt(2 mu g D)."""
    return math.sqrt(2.0 * DECEL * distance)


class Hammers:
    """Sweeping bars rotating about a vertical post; a hit knocks a racer along the sweep."""

    def __init__(self, course: Course, index: SceneIndex) -> None:
        self.items = course.hammers
        self.n = len(self.items)
        self.mocap = index.hammer_mocap
        self.phase = np.array([h.phase for h in self.items])
        self.omega = np.array([h.omega for h in self.items])
        self.x_lo = min((h.px - h.arm - 1.0 for h in self.items), default=math.inf)
        self.x_hi = max((h.px + h.arm + 1.0 for h in self.items), default=-math.inf)

    def pose(self, data: mujoco.MjData, t: float) -> None:
        """Turn the (visual) bars to their angle at time ``t``."""
        if self.n:
            half = 0.5 * (self.phase + self.omega * t)
            data.mocap_quat[self.mocap, 0] = np.cos(half)
            data.mocap_quat[self.mocap, 3] = np.sin(half)

    def hit(self, x: float, y: float, feet: float, t0: float, t1: float) -> tuple[float, float, float] | None:
        """(dir_x, dir_y, knock distance) if a bar swept over (x, y) during [t0, t1], else None."""
        if not self.x_lo <= x <= self.x_hi:
            return None
        for h in self.items:
            dx, dy = x - h.px, y - h.py
            r = math.hypot(dx, dy)
            if r > h.arm + RACER_RADIUS or feet >= h.floor + h.bar_top or feet < h.floor - 0.5:
                continue
            phi = math.atan2(dy, dx)
            sgn = 1.0 if h.omega > 0 else -1.0
            hw = (0.15 + RACER_RADIUS) / max(r, 0.3)
            period = 2 * math.pi / h.arms
            d = ((phi - (h.phase + h.omega * t0) + sgn * hw) * sgn) % period
            if d <= abs(h.omega) * (t1 - t0) + 2 * hw:
                return -sgn * math.sin(phi), sgn * math.cos(phi), h.knock
        return None

    def near(self, x: float, y: float) -> bool:
        """Whether (x, y) is within a bar's reach."""
        if not self.x_lo <= x <= self.x_hi:
            return False
        return any(math.hypot(x - h.px, y - h.py) <= h.arm + RACER_RADIUS for h in self.items)


class Trampolines:
    """Scripted launch pads: a racer standing on a pad gets v = sqrt(2 g H) / n_z * n."""

    def __init__(self, course: Course) -> None:
        self.items = course.trampolines
        self.n = len(self.items)
        self.vel = [(math.tan(t.tilt) * math.sqrt(2 * GRAVITY * t.height), math.sqrt(2 * GRAVITY * t.height))
                    for t in self.items]

    def pad(self, x: float, y: float, feet: float) -> int:
        """Index of the pad the feet at (x, y, feet) stand on, or -1."""
        for k, t in enumerate(self.items):
            if abs(x - t.cx) <= t.hx and abs(y - t.cy) <= t.hy and abs(feet - t.top) < 0.12:
                return k
        return -1


class Tiles:
    """Collapsing floor tiles (mocap bodies): drop ``delay`` s after first stood on."""

    def __init__(self, course: Course, index: SceneIndex, grids: CourseGrids) -> None:
        ts = course.tiles
        self.n = len(ts)
        self.grids = grids
        self.mocap = index.tile_mocap
        self.z0 = np.array([t.top - 0.25 for t in ts])
        self.collapses = [t.collapses for t in ts]
        self.delay = np.array([t.delay for t in ts])
        self.returns = np.array([t.returns for t in ts], bool)
        self.return_time = np.array([t.return_time for t in ts])
        self.reset()

    def reset(self) -> None:
        self.trigger = np.full(self.n, np.inf)
        self.drop_t = np.full(self.n, np.inf)
        self.down = np.zeros(self.n, bool)
        self.pending = 0  # tiles triggered or down

    def touch(self, k: int, t: float) -> None:
        """A racer stands on tile ``k`` at time ``t``: start its timer if it collapses."""
        if self.collapses[k] and self.trigger[k] == np.inf:
            self.trigger[k] = t
            self.pending += 1

    def update(self, data: mujoco.MjData, t: float) -> None:
        """Drop, animate and return tiles at time ``t``."""
        if not self.pending:
            return
        start = ~self.down & (t >= self.trigger + self.delay)
        for j in np.flatnonzero(start):
            self.down[j] = True
            self.drop_t[j] = self.trigger[j] + self.delay[j]
            self.grids.set_tile(int(j), False)
        back = self.down & self.returns & (t >= self.drop_t + self.return_time)
        for j in np.flatnonzero(back):
            self.down[j] = False
            self.trigger[j] = self.drop_t[j] = np.inf
            self.pending -= 1
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
        self.burst = np.zeros(self.n, bool)
        if self.n:
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
