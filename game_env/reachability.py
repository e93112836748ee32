"""Reachability check of a course graph: walk, jump, sprint-jump and trampoline reach."""

from __future__ import annotations

import math

from game_env.constants import (
    COOLDOWN,
    JUMP_HEIGHT,
    MAX_RAMP_DEG,
    REACH_SAFETY,
    RUN_SPEED,
    SPRINT_SPEED,
    TRAMP_MARGIN,
    WALK_STEP,
    jump_airtime,
)
from game_env.course import Course, Surface

MODES = ("walk", "jump", "sprint_jump", "trampoline")


def jump_reach(speed: float, dh: float) -> float:
    """Horizontal gap (m) a jump at ``speed`` is trusted to clear while landing ``dh`` higher."""
    if dh > JUMP_HEIGHT - 0.25:
        return -1.0
    t = jump_airtime(dh)
    return -1.0 if math.isnan(t) else REACH_SAFETY * speed * t


def edge_mode(course: Course, a: Surface, b: Surface) -> str | None:
    """Cheapest move that gets from surface ``a`` to ``b``, or None if none does."""
    gap = b.x0 - a.x1
    dh = b.z0 - a.z1
    if gap < 0.05 and dh <= WALK_STEP:
        return "walk"
    if gap <= jump_reach(RUN_SPEED, dh):
        return "jump"
    if gap <= jump_reach(SPRINT_SPEED, dh):
        return "sprint_jump"
    if a.kind == "trampoline":
        tramp = course.trampolines[a.ref]
        if gap < 0.05 and dh <= tramp.height - TRAMP_MARGIN:
            return "trampoline"
    return None


def surface_ok(course: Course, s: Surface) -> bool:
    """Whether a racer can cross surface ``s`` itself (belts, tiles, ramps)."""
    if s.kind == "ramp":
        return math.degrees(math.atan2(abs(s.z1 - s.z0), s.x1 - s.x0)) <= MAX_RAMP_DEG
    if s.kind == "conveyor":
        vx, vy = course.boxes[s.ref].belt
        if vx < 0:
            return -vx <= SPRINT_SPEED - 1.5
        return abs(vy) <= SPRINT_SPEED / math.sqrt(2) - 0.5
    if s.kind == "tiles":
        tiles = [t for t in course.tiles if s.x0 <= t.cx <= s.x1]
        if any(t.collapses for t in tiles):
            delay = min(t.delay for t in tiles if t.collapses)
            return delay >= 2.0 / SPRINT_SPEED + 0.15
    if s.kind == "hammer":
        return COOLDOWN < 1.0
    return True


def check_course(course: Course) -> list[str] | None:
    """Return the move needed for each edge of the course graph, or None if unsolvable."""
    surfaces = course.surfaces
    if not all(surface_ok(course, s) for s in surfaces):
        return None
    modes: list[str] = []
    for a, b in zip(surfaces[:-1], surfaces[1:], strict=True):
        mode = edge_mode(course, a, b)
        if mode is None:
            return None
        modes.append(mode)
    return modes


def is_reachable(course: Course) -> bool:
    """Whether the reachability check accepts ``course`` (every edge has a feasible move)."""
    return check_course(course) is not None
