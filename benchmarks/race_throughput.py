"""Obstacle race: end-to-end env steps/s of PPO and PPO+ASOR, 1 and 2 env runners.

For each env-runner count this runs `benchmarks.asor_overhead` on `game_env/ObstacleRace-v0`
(its race branch: `race_ppo_config`, the race network, ASOR with `RACE_ASOR_OBS_KEYS`) in a
fresh process: PPO and PPO+ASOR are built side by side and their iterations interleaved, the
warm-up iterations dropped; throughput = env steps of an iteration / `time_this_iter_s`
(sampling + learning). Target: ASOR/PPO ≥ 0.8.

    python -m benchmarks.race_throughput --runners 1 2 --iters 6 --out benchmarks/out/race_throughput

Writes OUT/game_env_ObstacleRace-v0-r<N>.{json,md} (from asor_overhead) and OUT/table.md.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ENV = "game_env/ObstacleRace-v0"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--runners", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--iters", type=int, default=6, help="iterations per algorithm")
    parser.add_argument("--warmup", type=int, default=1)
    parser.add_argument("--batch", type=int, default=1024, help="train batch (env steps)")
    parser.add_argument("--epochs", type=int, default=4)
    parser.add_argument("--envs-per-runner", type=int, default=4)
    parser.add_argument("--out", default="benchmarks/out/race_throughput")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    rows = []
    for n in args.runners:
        t0 = time.time()
        cmd = [
            sys.executable, "-m", "benchmarks.asor_overhead", "--env", ENV,
            "--env-runners", str(n), "--iters", str(args.iters), "--warmup", str(args.warmup),
            "--batch", str(args.batch), "--epochs", str(args.epochs),
            "--envs-per-runner", str(args.envs_per_runner), "--out", str(out),
        ]  # fmt: skip
        subprocess.run(cmd, check=True, env=env)
        summary = json.loads((out / f"{ENV.replace('/', '_')}-r{n}.json").read_text())
        summary["wall_s"] = time.time() - t0
        rows.append(summary)
    lines = [
        "| env runners | PPO env steps/s | PPO+ASOR env steps/s | ASOR/PPO (medians) "
        "| ASOR/PPO (paired, median) | target | iterations measured | wall (s) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for s in rows:
        med = s["steps_per_s_median"]
        lines.append(
            f"| {s['env_runners']} | {med['PPO']:.0f} | {med['PPO+ASOR']:.0f} "
            f"| {s['ratio_of_medians']:.2f} | {s['paired_ratio_median']:.2f} | ≥ 0.8 "
            f"| {s['iters_measured']} per algorithm | {s['wall_s']:.0f} |"
        )
    md = "\n".join(lines) + "\n"
    (out / "table.md").write_text(md)
    (out / "summary.json").write_text(json.dumps(rows, indent=1))
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
