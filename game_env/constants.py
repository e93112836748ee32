"""Physical constants shared by the generator, the simulator and the scripted racer."""

from __future__ import annotations

import math

GRAVITY = 9.81
TIMESTEP = 0.002  # s per mj_step
FRAME_SKIP = 20  # mj_steps per env step (env step = 0.04 s)
FRICTION = 0.4  # emulated sliding friction of a knocked racer (decel = FRICTION * g)

RACER_RADIUS = 0.3
RACER_HALF = 0.35  # half length of the capsule's cylinder
FEET = RACER_RADIUS + RACER_HALF  # centre height above the feet
RACER_MASS = 10.0
RACER_KV = 1000.0  # velocity-actuator gain (N per m/s)
RACER_FORCE = 150.0  # actuator force limit (N)

RUN_SPEED = 4.0
SPRINT_SPEED = 6.5
JUMP_HEIGHT = 1.2
JUMP_SPEED = math.sqrt(2.0 * GRAVITY * JUMP_HEIGHT)
DASH_SPEED = 8.0
DASH_TIME = 0.3
ATTACK_RANGE = 1.3
ATTACK_KNOCK = 1.5  # knock-back distance of an Attack (m)
COOLDOWN = 0.5  # s between jumps/attacks/dashes

# Reach limits used by the reachability check (conservative against the real physics).
WALK_STEP = 0.3  # highest step a racer walks up
REACH_SAFETY = 0.7  # fraction of the ballistic range the checker trusts
TRAMP_MARGIN = 0.5  # a trampoline must launch this much above the ledge it serves
MAX_RAMP_DEG = 35.0
FALL_DEPTH = 4.0  # below the lowest floor: fallen


def jump_airtime(dh: float, vz: float = JUMP_SPEED) -> float:
    """Time until a jump with upward speed ``vz`` lands ``dh`` above its take-off (nan if never)."""
    disc = vz * vz - 2.0 * GRAVITY * dh
    if disc < 0.0:
        return float("nan")
    return (vz + math.sqrt(disc)) / GRAVITY
