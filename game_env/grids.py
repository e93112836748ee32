"""Precomputed numpy maps of a course and batched 16x16 grid extraction for N racers.

The course is rasterised once on a fine 0.25 m grid, then block-reduced (max) to each cell
size the observation uses. Observation grids are plain index arithmetic on these maps.
Collapsing tiles change the terrain maps at run time (``set_tile``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy.ndimage import distance_transform_edt

from game_env.course import Course
from game_env.spaces import GRID, ITEM_TYPES, TERRAIN_TYPES

try:  # the clip ufunc itself (np.clip adds a Python wrapper per call)
    from numpy._core.umath import clip as _clip
except ImportError:  # pragma: no cover - older numpy
    from numpy.core.umath import clip as _clip

FINE = 0.25
VOID = -100.0
HALF = GRID // 2
RES_TERRAIN = (1.0, 2.0)
RES_ZONES = (1.0, 4.0, 16.0)


def _pool(arr: np.ndarray, fill: float, k: int) -> np.ndarray:
    """Max-pool a fine map by ``k`` and pad it by ``GRID`` cells of ``fill`` on each side."""
    fx, fy = -(-arr.shape[0] // k) * k, -(-arr.shape[1] // k) * k
    buf = np.full((fx, fy), fill, dtype=np.float32)
    buf[: arr.shape[0], : arr.shape[1]] = arr
    red = buf.reshape(fx // k, k, fy // k, k).max(axis=(1, 3))
    out = np.full((red.shape[0] + 2 * GRID, red.shape[1] + 2 * GRID), fill, dtype=np.float32)
    out[GRID : GRID + red.shape[0], GRID : GRID + red.shape[1]] = red
    return out


class CourseGrids:
    """Height/type/item/zone maps of one course, and the observation grids they give."""

    def __init__(self, course: Course, num_racers: int = 1) -> None:
        self.course = course
        hy = course.width / 2 + 1.0
        self.x_min = course.surfaces[0].x0 - 2.0
        self.y_min = -hy
        nx = int(math.ceil((course.length + 2.0 - self.x_min) / FINE))
        ny = int(math.ceil(2 * hy / FINE))
        xs = self.x_min + (np.arange(nx) + 0.5) * FINE
        ys = self.y_min + (np.arange(ny) + 0.5) * FINE
        self.xs, self.ys = xs, ys
        self.nx, self.ny = nx, ny
        self.static_h = np.full((nx, ny), VOID, np.float32)
        self.static_t = np.zeros((nx, ny), np.float32)
        self.items = np.zeros((nx, ny), np.float32)
        self.tile_id = np.full((nx, ny), -1, np.int32)
        self.belt_x = np.zeros((nx, ny), np.float64)
        self.belt_y = np.zeros((nx, ny), np.float64)
        self._rasterise()
        self.tile_alive = np.ones(len(course.tiles), bool)
        self.fine_h, self.fine_t = self._compose()
        solid = self.fine_h > VOID / 2
        self.cliff = (distance_transform_edt(solid) * FINE).astype(np.float32)
        self.num_racers = num_racers
        self.n_archives = len(course.archives)
        archives = self._zone_fine(course.archives)
        goals = self._zone_fine(list(course.goals) + [course.destination])
        # Per resolution: origin, pooled zone ids (int) and per-racer stacks (N, C, X, Y).
        self.res = np.array([1.0, 2.0, 4.0, 16.0])
        self.inv_res = 1.0 / self.res
        self.origin = np.stack([(self.x_min - GRID * self.res), (self.y_min - GRID * self.res)])
        ks = [int(round(r / FINE)) for r in self.res]
        self.zone_ids = {}  # (res index, 0=archive/1=goal) -> int map
        for i in (0, 2, 3):
            self.zone_ids[(i, 0)] = _pool(archives, 0.0, ks[i]).astype(np.intp)
            self.zone_ids[(i, 1)] = _pool(goals, 0.0, ks[i]).astype(np.intp)
        shape = [self.zone_ids[(0, 0)].shape, _pool(self.fine_h, VOID, ks[1]).shape,
                 self.zone_ids[(2, 0)].shape, self.zone_ids[(3, 0)].shape]
        chans = (5, 3, 2, 2)  # res 1: h, t, items, archive, goal; res 2: h, t, items; 4/16: zones
        # Every (layer, racer, channel) plane lives in one 2-D buffer of common width, so that a
        # sliding-window view of it gives any 16x16 window of any plane: one fancy index then
        # copies all twelve grid channels of all racers.
        width = max(sh[1] for sh in shape)
        rows = [num_racers * c * sh[0] for c, sh in zip(chans, shape, strict=True)]
        self.buf = np.zeros((sum(rows), width), np.float32)
        offs = np.cumsum([0, *rows])
        self.stacks = [self.buf[o : o + nr].reshape(num_racers, c, sh[0], width)[..., : sh[1]]
                       for o, nr, c, sh in zip(offs[:-1], rows, chans, shape, strict=True)]
        self.windows = sliding_window_view(self.buf, (GRID, GRID))
        out = [(0, 0), (0, 1), (1, 0), (1, 1), (0, 2), (1, 2), (0, 3), (2, 0), (3, 0), (0, 4), (2, 1), (3, 1)]
        self.layer_of = np.array([lay for lay, _ in out])
        # Per output channel (12): window-corner origin, 1 / cell size, largest corner, and the
        # buffer row of each racer's plane; corners come out as (N, 2, 12) without transposes.
        corner = self.origin + HALF * self.res  # (2, 4): origin of the window corner per layer
        self.corner = corner[:, self.layer_of]  # (2, 12)
        self.inv = self.inv_res[self.layer_of]  # (12,)
        self.max_ij = (np.array(shape, np.intp).T - GRID)[:, self.layer_of]  # (2, 12)
        self.row_base = np.array([offs[lay] + (np.arange(num_racers) * chans[lay] + ch) * shape[lay][0]
                                  for lay, ch in out], np.intp).T.copy()  # (N, 12)
        self._fill_terrain()
        self.archive_state = np.zeros((num_racers, self.n_archives + 1), np.float32)
        self.goal_state = np.zeros((num_racers, len(goals_list := list(course.goals)) + 2), np.float32)
        self.n_goals = len(goals_list) + 1  # intermediate goals + the destination
        self.reset_zones()

    def _fill_terrain(self) -> None:
        """(Re)write the terrain/item channels of the res-1 and res-2 stacks (all racers)."""
        for i, k in ((0, 4), (1, 8)):
            self.stacks[i][:, 0] = _pool(self.fine_h, VOID, k) * 0.2
            self.stacks[i][:, 1] = _pool(self.fine_t, 0.0, k)
            self.stacks[i][:, 2] = _pool(self.items, 0.0, k)

    def _fill_zones(self, n: int) -> None:
        for i, c0 in ((0, 3), (2, 0), (3, 0)):
            self.stacks[i][n, c0] = self.archive_state[n][self.zone_ids[(i, 0)]]
            self.stacks[i][n, c0 + 1] = self.goal_state[n][self.zone_ids[(i, 1)]]

    def reset_zones(self) -> None:
        """Every zone unreached for every racer."""
        self.archive_state[:, 1:] = 1.0
        self.goal_state[:, 1:] = 1.0
        for n in range(self.num_racers):
            self._fill_zones(n)

    def mark_reached(self, n: int, kind: str, k: int) -> None:
        """Racer ``n`` reached archive point / goal ``k`` (the destination is goal ``len(goals)``)."""
        state = self.archive_state if kind == "archive" else self.goal_state
        state[n, k + 1] = 0.5
        self._fill_zones(n)

    # --- rasterisation ----------------------------------------------------------------
    def _span(self, cx: float, cy: float, hx: float, hy: float) -> tuple[slice, slice]:
        i0 = int(np.searchsorted(self.xs, cx - hx))
        i1 = int(np.searchsorted(self.xs, cx + hx))
        j0 = int(np.searchsorted(self.ys, cy - hy))
        j1 = int(np.searchsorted(self.ys, cy + hy))
        return slice(i0, i1), slice(j0, j1)

    def _put(self, sx: slice, sy: slice, h, code: int) -> None:
        cur = self.static_h[sx, sy]
        newh = np.broadcast_to(np.asarray(h, np.float32), cur.shape)
        take = newh >= cur
        cur[take] = newh[take]
        self.static_t[sx, sy][take] = code / 8.0

    def _rasterise(self) -> None:
        c, tt, it = self.course, TERRAIN_TYPES, ITEM_TYPES
        for b in c.boxes:
            if b.kind == "ramp":
                length = b.hx * 2 * math.cos(b.pitch)
                sx, sy = self._span(b.x0 + length / 2, b.cy, length / 2, b.hy)
                frac = (self.xs[sx] - b.x0) / length
                h = (b.z0 + (b.z1 - b.z0) * frac)[:, None]
                self._put(sx, sy, h, tt["ramp"])
                continue
            sx, sy = self._span(b.cx, b.cy, b.hx, b.hy)
            code = tt["conveyor"] if b.kind == "conveyor" else tt["platform"]
            self._put(sx, sy, b.cz + b.hz, code)
            if b.kind == "conveyor":
                self.items[sx, sy] = it["conveyor"] / 6.0
                self.belt_x[sx, sy], self.belt_y[sx, sy] = b.belt
        for tr in c.trampolines:
            sx, sy = self._span(tr.cx, tr.cy, tr.hx, tr.hy)
            self.static_t[sx, sy] = tt["trampoline"] / 8.0
            self.items[sx, sy] = it["trampoline"] / 6.0
        for k, tile in enumerate(c.tiles):
            sx, sy = self._span(tile.cx, tile.cy, tile.hx, tile.hy)
            self.tile_id[sx, sy] = k
            if tile.collapses:
                self.items[sx, sy] = it["collapsing"] / 6.0
        xx, yy = np.meshgrid(self.xs, self.ys, indexing="ij")
        for bal in c.balloons:
            mask = (xx - bal.x) ** 2 + (yy - bal.y) ** 2 <= bal.radius**2
            self.items[mask] = np.maximum(self.items[mask], it["balloon"] / 6.0)
        for ham in c.hammers:
            mask = (xx - ham.px) ** 2 + (yy - ham.py) ** 2 <= (ham.arm + 0.3) ** 2
            self.items[mask] = np.maximum(self.items[mask], it["hammer"] / 6.0)
        for px, py, _ in c.props:
            sx, sy = self._span(px, py, 0.5, 0.5)
            self.items[sx, sy] = it["prop"] / 6.0
        for code, zones in (("archive", c.archives), ("goal", c.goals), ("destination", [c.destination])):
            for z in zones:
                sx, sy = self._span(z.cx, z.cy, z.hx, z.hy)
                self.static_t[sx, sy] = tt[code] / 8.0

    def _zone_fine(self, zones) -> np.ndarray:
        """Fine map of zone numbers (k + 1; 0 = none)."""
        out = np.zeros((self.nx, self.ny), np.float32)
        for k, z in enumerate(zones):
            sx, sy = self._span(z.cx, z.cy, z.hx, z.hy)
            out[sx, sy] = k + 1
        return out

    def _compose(self) -> tuple[np.ndarray, np.ndarray]:
        h, t = self.static_h.copy(), self.static_t.copy()
        on = self.tile_id >= 0
        if on.any():
            alive = self.tile_alive[self.tile_id[on]]
            tops = np.array([tl.top for tl in self.course.tiles], np.float32)[self.tile_id[on]]
            h[on] = np.where(alive, np.maximum(h[on], tops), h[on])
            t[on] = np.where(alive, TERRAIN_TYPES["collapsing"] / 8.0, t[on])
        return h, t

    def set_tile(self, k: int, alive: bool) -> None:
        """Mark tile ``k`` present/absent and refresh the terrain maps."""
        if bool(self.tile_alive[k]) == alive:
            return
        self.tile_alive[k] = alive
        self._refresh()

    def _refresh(self) -> None:
        self.fine_h, self.fine_t = self._compose()
        self._fill_terrain()

    def reset_tiles(self) -> None:
        """All tiles present again."""
        if not self.tile_alive.all():
            self.tile_alive[:] = True
            self._refresh()

    # --- queries ----------------------------------------------------------------------
    def fine_index(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ix = np.clip(((x - self.x_min) / FINE).astype(np.int64), 0, self.nx - 1)
        iy = np.clip(((y - self.y_min) / FINE).astype(np.int64), 0, self.ny - 1)
        return ix, iy

    def floor_height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Floor top under each (x, y) (``VOID`` where there is none)."""
        ix, iy = self.fine_index(x, y)
        return self.fine_h[ix, iy]

    def cliff_distance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Horizontal distance (m) from each (x, y) to the nearest floor edge (0 over void)."""
        ix, iy = self.fine_index(x, y)
        return self.cliff[ix, iy]

    def observe(
        self, x: np.ndarray, y: np.ndarray, feet: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Batched grids for N racers: terrain (N,4,16,16), items (N,2,..), targets, goals (N,3,..)."""
        out = self.observe_all(np.stack((x, y), axis=1), feet * 0.2)
        return out[:, 0:4], out[:, 4:6], out[:, 6:9], out[:, 9:12]

    def observe_all(self, xy: np.ndarray, feet5: np.ndarray) -> np.ndarray:
        """All twelve grid channels (N, 12, 16, 16) from positions ``xy`` (N, 2) and feet / 5 m (N,).

        Channels: terrain 0-3, items 4-5, targets 6-8, goals 9-11. One fancy index of the
        sliding-window view copies them all.
        """
        ij = xy[:, :, None] - self.corner
        ij *= self.inv
        ij = ij.astype(np.intp)  # (N, 2, 12) window corners
        _clip(ij, 0, self.max_ij, out=ij)
        rows = ij[:, 0]
        rows += self.row_base
        out = self.windows[rows, ij[:, 1]]  # (N, 12, 16, 16)
        hts = out[:, 0:4:2]
        hts -= feet5.reshape(-1, 1, 1, 1)
        _clip(hts, -1.0, 1.0, out=hts)
        return out
