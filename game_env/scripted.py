"""A scripted racer that follows the course graph: the expert reference for each map.

It reads the simulator's privileged state (course graph, positions, hammer phases): it jumps
gaps and steps at their edges, walks onto trampolines and steers onto the ledge, sprints over
collapsing tiles, counter-steers on belts and times jumps over sweeping hammers.

    python -m game_env.scripted --map 3 --seed 0      # prints the episode metrics
"""

from __future__ import annotations

import argparse
import json
from typing import Any

import numpy as np

from game_env.constants import (
    FEET,
    GRAVITY,
    JUMP_SPEED,
    RACER_FORCE,
    RACER_MASS,
    RACER_RADIUS,
    SPRINT_SPEED,
)
from game_env.sim import RaceSim

ACCEL = RACER_FORCE / RACER_MASS


class ScriptedRacer:
    """Policy for racer ``racer``; call ``act()`` once per env step.

    ``source`` is a ``RaceSim``, a ``gymnasium.make``'d race env (wrapped or not) or the
    PettingZoo env; ``racer`` is an index or an agent name ("racer_2").
    """

    def __init__(self, source: Any, racer: int | str = 0) -> None:
        sim = source if isinstance(source, RaceSim) else getattr(source, "sim", None)
        if sim is None:
            sim = getattr(getattr(source, "unwrapped", None), "sim", None)
        if not isinstance(sim, RaceSim):
            raise ValueError(f"source={source!r} is not valid; allowed: a RaceSim or a game_env env")
        self.sim = sim
        self.i = int(racer[6:]) if isinstance(racer, str) and racer.startswith("racer_") else int(racer)
        if not 0 <= self.i < sim.n:
            raise ValueError(f"racer={racer!r} is out of range; allowed: 0..{sim.n - 1}")
        self.seg = 0

    def __call__(self, observation: Any = None) -> np.ndarray:
        """Same as ``act``; the observation is not needed (the racer reads the simulator)."""
        return self.act()

    def _surface(self, x: float, feet: float, grounded: bool) -> int:
        surfaces = self.sim.course.surfaces
        if not grounded:
            return self.seg
        best, err = self.seg, 1e9
        for k, s in enumerate(surfaces):
            if s.x0 - 0.3 <= x <= s.x1 + 0.3:
                frac = min(max((x - s.x0) / max(s.x1 - s.x0, 1e-6), 0.0), 1.0)
                e = abs(feet - (s.z0 + frac * (s.z1 - s.z0)))
                if e < err:
                    best, err = k, e
        return best

    def _hammer_eta(self, x: float, y: float, vx: float, vy: float, feet: float, t: float) -> float:
        """Seconds until a hammer bar sweeps over the racer's predicted position (inf if none)."""
        hammers = self.sim.hammers
        if not hammers.n or not hammers.x_lo - 3.0 <= x <= hammers.x_hi:
            return float("inf")
        dt = 0.04
        for k in range(1, 21):
            tau = k * dt
            if hammers.hit(x + vx * tau, y + vy * tau, feet, t + tau - dt, t + tau) is not None:
                return tau
        return float("inf")

    def act(self, observation: Any = None) -> np.ndarray:
        """The action of this env step: MultiDiscrete([3,3,2,2,2,2,8,2]) as an int array."""
        sim, i = self.sim, self.i
        r = sim.racers[i]
        x, y, z = (float(v) for v in sim.data.qpos[sim.qpos_i[i]])
        vx, vy, _ = (float(v) for v in sim.data.qvel[sim.qvel_i[i]])
        feet, t = z - FEET, float(sim.data.time)
        grounded = r.grounded
        self.seg = self._surface(x, feet, grounded)
        surfaces, edges = sim.course.surfaces, sim.course.edges
        s = surfaces[self.seg]
        mx, sprint, jump = 1, 1, 0
        target_y = 0.0
        last = self.seg == len(surfaces) - 1
        if last:
            d = sim.course.destination
            mx = 0 if abs(x - d.cx) < 0.3 else (1 if x < d.cx else -1)
            target_y, sprint = d.cy, 0
        else:
            mode = edges[self.seg]
            sprint = int(mode != "jump")  # a running jump is enough; sprinting overshoots
            if mode in ("jump", "sprint_jump"):
                nxt = surfaces[self.seg + 1]
                climb = nxt.x0 - s.x1 < 0.05
                if grounded and x >= s.x1 - (0.7 if climb else 0.35):
                    jump = 1
            elif mode == "trampoline":
                sprint = 0
        if r.launched and self.seg + 1 < len(surfaces):  # in a trampoline flight: land past the ledge
            nxt = surfaces[self.seg + 1]
            sprint = 0
            mx = 1 if x < nxt.x0 + 1.0 else (-1 if x > nxt.x0 + 1.8 else 0)
        if r.in_jump and not r.launched and self.seg + 1 < len(surfaces):  # stop over the landing
            nxt = surfaces[self.seg + 1]
            if x > nxt.x0 + min(1.2, 0.5 * (nxt.x1 - nxt.x0)):
                mx = 0
        ham = self._next_hammer(x)
        if ham is not None and x > ham.px - ham.arm - 3.0:
            wait_x = ham.px - ham.arm - 0.6
            target_y = ham.py
            if x < wait_x - 0.25:
                mx, sprint = 1, 0  # walk up to the waiting spot outside the sweep
            elif x <= wait_x + 0.3:
                go = not grounded or self._clear_jump(ham, x, y, vx, feet, t)
                mx, sprint, jump = (1, 1, int(grounded)) if go else (0, 0, 0)
            else:  # inside the sweep: keep going, hop if the bar is about to arrive
                mx, sprint = 1, 1
                eta = self._hammer_eta(x, y, vx, vy, feet, t)
                jump = int(grounded and 0.2 <= eta <= 0.5)
        # Lateral: hold target_y against belts.
        bx, by = r.belt if grounded else (0.0, 0.0)
        want = -by - 2.0 * (y - target_y)
        my = 1 if want > 0.8 else (-1 if want < -0.8 else 0)
        return np.array([mx + 1, my + 1, jump, sprint, 0, 0, 0, 0], dtype=np.int64)

    def _next_hammer(self, x: float):
        ahead = [h for h in self.sim.course.hammers if x < h.px + h.arm + RACER_RADIUS + 0.1]
        return min(ahead, key=lambda h: h.px) if ahead else None

    def _clear_jump(self, ham, x: float, y: float, vx: float, feet: float, t: float) -> bool:
        """Whether a sprinting jump started now clears every sweep until past the hammer."""
        hammers = self.sim.hammers
        exit_x = ham.px + ham.arm + RACER_RADIUS + 0.1
        dt, tau, v = 0.02, 0.0, max(vx, 0.0)
        while x < exit_x and tau < 2.5:
            v = min(SPRINT_SPEED, v + ACCEL * dt)
            x += v * dt
            tau += dt
            z = feet + max(JUMP_SPEED * tau - 0.5 * GRAVITY * tau * tau, 0.0)
            if hammers.hit(x, y, z, t + tau - dt, t + tau) is not None:
                return False
        return True


def run_episode(map_id: int, course_seed: int, max_episode_steps: int = 1000) -> dict[str, float]:
    """Run the scripted racer alone on (map_id, course_seed); return its episode metrics."""
    sim = RaceSim(1, max_episode_steps=max_episode_steps)
    sim.load(map_id, course_seed)
    sim.reset()
    policy = ScriptedRacer(sim)
    for _ in range(max_episode_steps):
        _, _, done, err = sim.step(policy.act()[None])
        if done[0] or err:
            break
    return sim.episode_metrics(0)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--map", type=int, default=0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=1000)
    args = parser.parse_args(argv)
    print(json.dumps(run_episode(args.map, args.seed, args.steps), indent=1))


if __name__ == "__main__":
    main()
