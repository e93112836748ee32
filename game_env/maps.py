"""The ten maps: layout mix and per-map ranges of every element's behaviour.

A map is a recipe, not a course: ``generator.generate_course(map_id, seed)`` draws the actual
values from these ranges. Ranges are (low, high) and drawn uniformly.
"""

from __future__ import annotations

from dataclasses import dataclass, field

NUM_MAPS = 10

Range = tuple[float, float]


@dataclass(frozen=True)
class MapSpec:
    """Per-map generation recipe; every behaviour has a range."""

    name: str
    description: str
    segment_weights: dict[str, float]
    n_segments: tuple[int, int] = (7, 9)
    width: Range = (6.0, 8.0)
    platform_len: Range = (4.0, 7.0)
    gap_len: Range = (1.0, 2.5)
    gap_dh: Range = (-0.8, 0.5)
    ramp_dh: Range = (-1.5, 1.5)
    step_dh: Range = (0.3, 0.8)
    conveyor_speed: Range = (1.0, 2.0)
    conveyor_dirs: tuple[str, ...] = ("forward", "back")
    conveyor_len: Range = (6.0, 10.0)
    tramp_height: Range = (2.5, 3.5)
    tramp_tilt_deg: Range = (0.0, 10.0)
    hammer_speed: Range = (1.0, 2.0)
    hammer_knock: Range = (1.5, 2.5)
    hammer_arms: tuple[int, int] = (1, 1)
    balloon_stiffness: Range = (3.0, 8.0)
    balloon_count: tuple[int, int] = (3, 6)
    balloon_burst_prob: float = 0.0
    tile_delay: Range = (1.0, 2.0)
    tile_collapse_frac: Range = (0.3, 0.6)
    tile_return_prob: float = 1.0
    tile_return_time: Range = (2.0, 4.0)
    prop_prob: float = 0.2
    archive_every: int = 3
    goal_every: int = 2
    dest_size: Range = (1.5, 2.5)
    extra: dict[str, float] = field(default_factory=dict)


MAPS: tuple[MapSpec, ...] = (
    MapSpec(
        "meadow",
        "easy: flat platforms, short gaps, gentle ramps",
        {"platform": 2, "gap": 2, "ramp": 1},
        gap_len=(0.8, 1.8),
        gap_dh=(-0.5, 0.3),
        ramp_dh=(-1.0, 1.0),
    ),
    MapSpec(
        "canyon",
        "many long gaps; some need a sprint-jump, a few draws are unsolvable and retried",
        {"gap": 4, "platform": 1, "step": 1},
        gap_len=(1.8, 5.0),
        gap_dh=(-1.0, 0.6),
    ),
    MapSpec(
        "stairs",
        "steps up and ramps: climbing jumps are needed",
        {"step": 3, "ramp": 2, "platform": 1, "gap": 1},
        step_dh=(0.4, 0.95),
        ramp_dh=(-2.0, 2.5),
    ),
    MapSpec(
        "factory",
        "strong conveyor belts, backwards and sideways",
        {"conveyor": 4, "platform": 1, "gap": 1},
        conveyor_speed=(2.0, 4.5),
        conveyor_dirs=("back", "left", "right"),
    ),
    MapSpec(
        "party",
        "balloon fields; balloons burst when touched",
        {"balloons": 3, "platform": 1, "gap": 1},
        balloon_stiffness=(2.0, 6.0),
        balloon_count=(4, 7),
        balloon_burst_prob=0.7,
    ),
    MapSpec(
        "skyline",
        "high trampolines up to tall platforms",
        {"trampoline": 3, "platform": 1, "gap": 1},
        tramp_height=(3.5, 5.0),
        tramp_tilt_deg=(5.0, 20.0),
    ),
    MapSpec(
        "crumble",
        "collapsing-tile bridges with short delays that do not return",
        {"collapse": 4, "platform": 1},
        n_segments=(5, 7),
        tile_delay=(0.45, 1.0),
        tile_collapse_frac=(0.5, 1.0),
        tile_return_prob=0.0,
    ),
    MapSpec(
        "hammertime",
        "fast sweeping hammers with long knock-back",
        {"hammers": 4, "platform": 1},
        n_segments=(4, 6),
        hammer_speed=(2.5, 4.0),
        hammer_knock=(3.0, 4.5),
        hammer_arms=(1, 2),
    ),
    MapSpec(
        "lowbounce",
        "weak trampolines, forward belts and gaps (the opposite of skyline/factory)",
        {"trampoline": 2, "conveyor": 2, "gap": 2},
        tramp_height=(1.6, 2.4),
        tramp_tilt_deg=(0.0, 5.0),
        conveyor_speed=(1.0, 2.5),
        conveyor_dirs=("forward",),
        gap_len=(1.0, 3.0),
    ),
    MapSpec(
        "gauntlet",
        "everything, mid-range values",
        {
            "gap": 1,
            "ramp": 1,
            "step": 1,
            "conveyor": 1,
            "balloons": 1,
            "trampoline": 1,
            "collapse": 1,
            "hammers": 1,
        },
        n_segments=(8, 10),
        conveyor_speed=(1.5, 3.5),
        conveyor_dirs=("forward", "back", "left", "right"),
        hammer_speed=(1.5, 3.0),
        hammer_knock=(2.0, 3.5),
        tramp_height=(2.5, 4.0),
        tile_delay=(0.7, 1.5),
        balloon_burst_prob=0.5,
    ),
)


def map_spec(map_id: int) -> MapSpec:
    """Return the recipe of ``map_id``; ``ValueError`` if it is not an int in 0..9."""
    return MAPS[check_map_id(map_id)]


def check_map_id(map_id: object) -> int:
    """Validate a map id and return it as an int."""
    if isinstance(map_id, bool) or not isinstance(map_id, (int,)) and not (
        hasattr(map_id, "__index__") and not isinstance(map_id, float)
    ):
        raise ValueError(f"map_id={map_id!r} is not valid; allowed: an int in 0..{NUM_MAPS - 1}")
    value = int(map_id)  # type: ignore[arg-type]
    if not 0 <= value < NUM_MAPS:
        raise ValueError(f"map_id={map_id!r} is out of range; allowed: 0..{NUM_MAPS - 1}")
    return value
