"""`make bench`: the quick benchmarks in one go (speed ratios; the learning studies are separate).

Each writes JSON + markdown under benchmarks/out/. Learning benchmarks take much longer and are
run on their own (see docs/results.md for their commands):
`studies.lib.lava_reproduction`, `studies.lib.race_learning`, `studies.lib.mujoco_shift`,
`studies.lib.traffic_density` (studies/README.md), `benchmarks/soak.py`.
"""

from __future__ import annotations

import subprocess
import sys

QUICK = [
    [sys.executable, "benchmarks/env_speed.py", "--steps", "2000", "--repeats", "3"],
    [sys.executable, "-m", "benchmarks.asor_overhead", "--iters", "12"],
    [sys.executable, "-m", "benchmarks.asor_overhead", "--env", "game_env/ObstacleRace-v0",
     "--env-runners", "2", "--batch", "1024", "--epochs", "4", "--iters", "8"],
]


def main() -> int:
    """Run every quick benchmark; the exit code is the first failure's, else 0."""
    for cmd in QUICK:
        print("+", " ".join(cmd), flush=True)
        code = subprocess.call(cmd)
        if code:
            return code
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
