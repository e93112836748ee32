"""Course generation: a course is a pure function of (map_id, seed).

A course is a sequence of segments along +x. Each segment leaves the racer on a plain
"exit" platform, where archive points and intermediate goals are placed. The path is kept as
a list of ``Surface`` nodes; ``reachability.check_course`` accepts or rejects a draw and the
generator retries with the next sub-seed.
"""

from __future__ import annotations

import math

import numpy as np

from game_env.course import Balloon, Box, Course, Hammer, Surface, Tile, Trampoline, Zone
from game_env.maps import MapSpec, check_map_id, map_spec
from game_env.reachability import check_course

PLATFORM_HZ = 0.5  # half thickness of floor boxes
MAX_ATTEMPTS = 64


class _Builder:
    """Appends segments to a course while drawing from one numpy Generator."""

    def __init__(self, spec: MapSpec, rng: np.random.Generator, course: Course) -> None:
        self.spec, self.rng, self.c = spec, rng, course
        self.x, self.h = 0.0, 0.0
        self.hy = course.width / 2.0

    def u(self, rng_range: tuple[float, float]) -> float:
        return float(self.rng.uniform(*rng_range))

    def platform(self, length: float, kind: str = "platform", belt=(0.0, 0.0)) -> Surface:
        x0 = self.x
        self.c.boxes.append(
            Box(x0 + length / 2, 0.0, self.h - PLATFORM_HZ, length / 2, self.hy, PLATFORM_HZ,
                kind, belt=belt)
        )
        self.x += length
        s = Surface(kind, x0, self.x, self.h, self.h)
        self.c.surfaces.append(s)
        return s

    def exit_pad(self) -> Surface:
        s = self.platform(round(self.u((3.0, 5.0)), 2))
        if self.rng.random() < self.spec.prop_prob:
            self.c.props.append((s.x0 + 1.5, float(self.rng.uniform(-1, 1)) * (self.hy - 1), s.z0 + 0.5))
        return s

    # --- segments -------------------------------------------------------------------
    def seg_platform(self) -> None:
        self.exit_pad()
        self.platform(round(self.u(self.spec.platform_len), 2))

    def seg_gap(self) -> None:
        self.x += round(self.u(self.spec.gap_len), 2)
        self.h += round(self.u(self.spec.gap_dh), 2)
        self.platform(round(self.u(self.spec.platform_len), 2))

    def seg_step(self) -> None:
        self.h += round(self.u(self.spec.step_dh), 2)
        self.platform(round(self.u(self.spec.platform_len), 2))

    def seg_ramp(self) -> None:
        dh = round(self.u(self.spec.ramp_dh), 2)
        length = round(max(3.0, abs(dh) / math.tan(math.radians(25.0)) + self.u((0.0, 2.0))), 2)
        a = math.atan2(dh, length)
        half = math.hypot(length, dh) / 2
        tx, tz = self.x + length / 2, self.h + dh / 2  # top-surface centre
        cx, cz = tx + PLATFORM_HZ * math.sin(a), tz - PLATFORM_HZ * math.cos(a)
        self.c.boxes.append(
            Box(cx, 0.0, cz, half, self.hy, PLATFORM_HZ, "ramp", pitch=-a, x0=self.x, z0=self.h,
                z1=self.h + dh)
        )
        self.c.surfaces.append(Surface("ramp", self.x, self.x + length, self.h, self.h + dh))
        self.x += length
        self.h += dh
        self.exit_pad()

    def seg_conveyor(self) -> None:
        speed = round(self.u(self.spec.conveyor_speed), 2)
        direction = self.spec.conveyor_dirs[int(self.rng.integers(len(self.spec.conveyor_dirs)))]
        belt = {"forward": (speed, 0.0), "back": (-speed, 0.0), "left": (0.0, speed),
                "right": (0.0, -speed)}[direction]
        s = self.platform(round(self.u(self.spec.conveyor_len), 2), "conveyor", belt)
        self.c.surfaces[-1] = Surface("conveyor", s.x0, s.x1, s.z0, s.z1, len(self.c.boxes) - 1)
        self.exit_pad()

    def seg_hammers(self) -> None:
        arm = round(self.hy - 0.3, 2)
        knock = round(self.u(self.spec.hammer_knock), 2)
        speed = self.u(self.spec.hammer_speed) * (1 if self.rng.random() < 0.5 else -1)
        arms = int(self.rng.integers(self.spec.hammer_arms[0], self.spec.hammer_arms[1] + 1))
        length = round(2 * arm + 2 * knock + 2.0, 2)
        s = self.platform(length, "hammer")
        self.c.hammers.append(
            Hammer(s.x0 + length / 2, 0.0, self.h, arm, round(speed, 3),
                   round(self.u((0.0, 2 * math.pi)), 3), knock, arms)
        )
        self.c.surfaces[-1] = Surface("hammer", s.x0, s.x1, s.z0, s.z1, len(self.c.hammers) - 1)
        self.exit_pad()

    def seg_balloons(self) -> None:
        length = round(self.u((8.0, 12.0)), 2)
        s = self.platform(length, "balloons")
        n = int(self.rng.integers(self.spec.balloon_count[0], self.spec.balloon_count[1] + 1))
        burst = bool(self.rng.random() < self.spec.balloon_burst_prob)
        k = round(self.u(self.spec.balloon_stiffness), 2)
        for _ in range(n):
            r = round(self.u((0.45, 0.7)), 2)
            self.c.balloons.append(
                Balloon(round(s.x0 + self.u((1.0, length - 1.0)), 2),
                        round(self.u((-self.hy + r, self.hy - r)), 2), s.z0 + 0.75, r, k, burst)
            )
        self.exit_pad()

    def seg_collapse(self) -> None:
        ncol = int(self.rng.integers(3, 6))
        nrow = max(2, int(round(self.c.width / 2.0)))
        tile_w = self.c.width / nrow
        delay = round(self.u(self.spec.tile_delay), 2)
        frac = self.u(self.spec.tile_collapse_frac)
        returns = bool(self.rng.random() < self.spec.tile_return_prob)
        rt = round(self.u(self.spec.tile_return_time), 2)
        x0 = self.x
        for i in range(ncol):
            for j in range(nrow):
                self.c.tiles.append(
                    Tile(x0 + 1.0 + 2.0 * i, -self.hy + tile_w * (j + 0.5), self.h, 0.98,
                         tile_w / 2 - 0.02, bool(self.rng.random() < frac), delay, returns, rt)
                )
        self.x += 2.0 * ncol
        self.c.surfaces.append(Surface("tiles", x0, self.x, self.h, self.h, len(self.c.tiles) - 1))
        self.exit_pad()

    def seg_trampoline(self) -> None:
        height = round(self.u(self.spec.tramp_height), 2)
        tilt = math.radians(self.u(self.spec.tramp_tilt_deg))
        s = self.platform(3.5, "trampoline")
        self.c.trampolines.append(
            Trampoline(s.x1 - 1.0, 0.0, self.h, 0.9, min(1.5, self.hy - 0.2), height, round(tilt, 4))
        )
        self.c.surfaces[-1] = Surface("trampoline", s.x0, s.x1, s.z0, s.z1,
                                      len(self.c.trampolines) - 1)
        self.h += round(self.u((1.1, max(1.2, height - 0.2))), 2)
        self.platform(round(self.u(self.spec.platform_len), 2))


def _draw(spec: MapSpec, map_id: int, seed: int, attempt: int) -> Course:
    rng = np.random.default_rng([seed, map_id, attempt])
    width = round(float(rng.uniform(*spec.width)), 1)
    course = Course(map_id, seed, attempt + 1, width)
    b = _Builder(spec, rng, course)
    b.x = -4.0
    b.platform(8.0, "start")
    course.start = (0.0, 0.0, 0.0)
    kinds = list(spec.segment_weights)
    p = np.array([spec.segment_weights[k] for k in kinds], dtype=float)
    n = int(rng.integers(spec.n_segments[0], spec.n_segments[1] + 1))
    for i in range(n):
        getattr(b, "seg_" + kinds[int(rng.choice(len(kinds), p=p / p.sum()))])()
        exit_s = course.surfaces[-1]
        if (i + 1) % spec.archive_every == 0 and i < n - 1:
            course.archives.append(Zone(exit_s.x0 + 1.0, 0.0, exit_s.z0, 0.8, b.hy))
        elif (i + 1) % spec.goal_every == 0 and i < n - 1:
            course.goals.append(Zone(exit_s.x1 - 1.0, 0.0, exit_s.z1, 0.8, b.hy))
    b.x += 0.0
    final = b.platform(8.0, "finish")
    size = round(b.u(spec.dest_size), 2)
    course.destination = Zone(final.x0 + 5.0, 0.0, final.z0, size / 2, size / 2,
                              round(b.u((0.0, math.pi / 2)), 3))
    return course


def generate_course(map_id: int, seed: int) -> Course:
    """Return the course of (map_id, seed): the first draw that passes the reachability check."""
    map_id = check_map_id(map_id)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed={seed!r} is not valid; allowed: an int >= 0")
    spec = map_spec(map_id)
    for attempt in range(MAX_ATTEMPTS):
        course = _draw(spec, map_id, int(seed), attempt)
        edges = check_course(course)
        if edges is not None:
            course.edges = edges
            return course
    raise RuntimeError(f"no solvable course for map_id={map_id} seed={seed} in {MAX_ATTEMPTS} tries")
