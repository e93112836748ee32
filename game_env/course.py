"""Course data: what a generated course is made of (no generation here, see ``generator``).

A course is a sequence of segments along +x, kept as floor boxes and hazard elements plus the
path as a list of ``Surface`` nodes (the course graph that ``reachability`` checks).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Box:
    """A static floor box; ``pitch`` (rad) tilts ramps about y; ``belt`` is surface velocity."""

    cx: float
    cy: float
    cz: float
    hx: float
    hy: float
    hz: float
    kind: str = "platform"
    pitch: float = 0.0
    belt: tuple[float, float] = (0.0, 0.0)
    x0: float = 0.0  # ramps: start x and start/end top heights
    z0: float = 0.0
    z1: float = 0.0


@dataclass(frozen=True)
class Trampoline:
    cx: float
    cy: float
    top: float
    hx: float
    hy: float
    height: float  # apex above the pad (m)
    tilt: float  # rad, pad normal tilted towards +x

    @property
    def normal(self) -> tuple[float, float, float]:
        return (math.sin(self.tilt), 0.0, math.cos(self.tilt))


@dataclass(frozen=True)
class Hammer:
    px: float
    py: float
    floor: float
    arm: float  # arm length (m)
    omega: float  # rad/s (sign = direction)
    phase: float  # rad
    knock: float  # knock-back distance (m)
    arms: int  # 1 or 2 (a bar through the pivot)
    bar_top: float = 0.7  # top of the bar above the floor


@dataclass(frozen=True)
class Balloon:
    x: float
    y: float
    z: float
    radius: float
    stiffness: float
    burst: bool


@dataclass(frozen=True)
class Tile:
    cx: float
    cy: float
    top: float
    hx: float
    hy: float
    collapses: bool
    delay: float
    returns: bool
    return_time: float


@dataclass(frozen=True)
class Zone:
    """Archive point, goal or destination: a box region above a floor (top at ``z``)."""

    cx: float
    cy: float
    z: float
    hx: float
    hy: float
    yaw: float = 0.0


@dataclass(frozen=True)
class Surface:
    """A node of the course graph: walkable from x0 to x1, top height z0 -> z1."""

    kind: str
    x0: float
    x1: float
    z0: float
    z1: float
    ref: int = -1  # index into the element list of its kind (trampolines, ...)


@dataclass
class Course:
    """Everything the scene, the grids, the simulator and the scripted racer need."""

    map_id: int
    seed: int
    attempts: int
    width: float
    boxes: list[Box] = field(default_factory=list)
    trampolines: list[Trampoline] = field(default_factory=list)
    hammers: list[Hammer] = field(default_factory=list)
    balloons: list[Balloon] = field(default_factory=list)
    tiles: list[Tile] = field(default_factory=list)
    archives: list[Zone] = field(default_factory=list)
    goals: list[Zone] = field(default_factory=list)
    props: list[tuple[float, float, float]] = field(default_factory=list)
    surfaces: list[Surface] = field(default_factory=list)
    edges: list[str] = field(default_factory=list)  # move needed from surface i to i+1
    destination: Zone | None = None
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def length(self) -> float:
        return self.surfaces[-1].x1

    @property
    def floor_min(self) -> float:
        return min(min(s.z0, s.z1) for s in self.surfaces)
