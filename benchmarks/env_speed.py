"""Race env speed: env steps/s and the ratio to raw ``mj_step`` of the same model / frame_skip.

    python benchmarks/env_speed.py [--steps 3000] [--repeats 3] [--maps 0 2 3 7 9] [--out benchmarks/out]

For 1 racer (``gymnasium.make("game_env/ObstacleRace-v0")``, wrappers included) and 8 racers
(``game_env.parallel_env``), random actions, resets included. Raw physics is ``mj_step`` on a
fresh ``MjData`` of the very same model (racers standing on the start pad). Env and raw runs
alternate ``--repeats`` times and the median ratio is reported. Rates are per second of CPU
time of this process (``time.process_time``), which a shared, noisy machine distorts much less
than wall time; wall-time env steps/s are reported beside them.
Gymnasium's Hopper-v5 is measured the same way as a reference. Writes ``env_speed.json`` and
``env_speed.md`` under ``--out``.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import game_env  # noqa: E402
from game_env.gl import import_mujoco  # noqa: E402

mujoco = import_mujoco()  # no GL library loaded: the benchmark runs on a machine without libEGL


def raw_rate(model: mujoco.MjModel, steps: int) -> float:
    """mj_step calls per CPU second on a fresh MjData of ``model``."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    mujoco.mj_step(model, data, nstep=50)
    t = time.process_time()
    mujoco.mj_step(model, data, nstep=steps)
    return steps / (time.process_time() - t)


def single_rate(env: gym.Env, actions: np.ndarray) -> tuple[float, float]:
    """(env steps per CPU second, per wall second)."""
    t, w = time.process_time(), time.perf_counter()
    for a in actions:
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
    return len(actions) / (time.process_time() - t), len(actions) / (time.perf_counter() - w)


def multi_rate(env, actions: np.ndarray) -> tuple[float, float]:
    names = env.possible_agents
    t, w = time.process_time(), time.perf_counter()
    for a in actions:
        env.step({n: a[i] for i, n in enumerate(names) if n in env.agents})
        if not env.agents:
            env.reset()
    return len(actions) / (time.process_time() - t), len(actions) / (time.perf_counter() - w)


def measure(kind: str, map_id: int, steps: int, repeats: int, rng: np.random.Generator) -> dict:
    if kind == "hopper":
        env = gym.make("Hopper-v5")
        env.reset(seed=0)
        acts = rng.uniform(-1, 1, (steps, 3)).astype(np.float32)
        run, racers = (lambda: single_rate(env, acts)), 1
    elif kind == "race1":
        env = gym.make("game_env/ObstacleRace-v0", map_id=map_id, course_seed=0)
        env.reset(seed=0)
        acts = rng.integers(0, game_env.spaces.ACTION_NVEC, (steps, 8))
        run, racers = (lambda: single_rate(env, acts)), 1
    else:
        env = game_env.parallel_env(num_racers=8, map_id=map_id, course_seed=0)
        env.reset(seed=0)
        acts = rng.integers(0, game_env.spaces.ACTION_NVEC, (steps, 8, 8))
        run, racers = (lambda: multi_rate(env, acts)), 8
    model, frame_skip = env.unwrapped.model, env.unwrapped.frame_skip
    env_rates, wall_rates, raw_rates, ratios = [], [], [], []
    for _ in range(repeats):
        raw = raw_rate(model, steps * frame_skip // 2)
        sps, wall = run()
        wall_rates.append(wall)
        raw2 = raw_rate(model, steps * frame_skip // 2)
        raw = 0.5 * (raw + raw2)
        env_rates.append(sps)
        raw_rates.append(raw)
        ratios.append(sps / (raw / frame_skip))
    return {"env": kind, "map_id": map_id if kind != "hopper" else None, "racers": racers,
            "frame_skip": frame_skip, "env_steps_per_s": statistics.median(env_rates),
            "env_steps_per_wall_s": statistics.median(wall_rates),
            "raw_mj_steps_per_s": statistics.median(raw_rates), "ratio": statistics.median(ratios),
            "ratios": ratios}


def to_markdown(rows: list[dict], meta: dict) -> str:
    lines = [f"`{meta['command']}` ({meta['machine']}, {meta['date']})", "",
             "| env | map | racers | frame_skip | env steps/s (CPU) | env steps/s (wall) | raw mj_step/s (CPU) "
             "| ratio env / (raw / frame_skip) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['env']} | {'-' if r['map_id'] is None else r['map_id']} | {r['racers']} | "
                     f"{r['frame_skip']} | {r['env_steps_per_s']:.0f} | {r['env_steps_per_wall_s']:.0f} | "
                     f"{r['raw_mj_steps_per_s']:.0f} | "
                     f"{r['ratio']:.2f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=3000)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--maps", type=int, nargs="+", default=[0, 2, 3, 7, 9])
    p.add_argument("--out", type=Path, default=Path("benchmarks/out"))
    args = p.parse_args(argv)
    rng = np.random.default_rng(0)
    rows = [measure("hopper", 0, args.steps, args.repeats, rng)]
    for kind in ("race1", "race8"):
        for m in args.maps:
            rows.append(measure(kind, m, args.steps, args.repeats, rng))
            print(json.dumps({k: v for k, v in rows[-1].items() if k != "ratios"}), flush=True)
    meta = {"command": "python " + " ".join(["benchmarks/env_speed.py", *(argv if argv is not None else sys.argv[1:])]),
            "machine": f"{platform.machine()}, {platform.processor() or 'cpu'}",
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "env_speed.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    md = to_markdown(rows, meta)
    (args.out / "env_speed.md").write_text(md)
    print(md)


if __name__ == "__main__":
    main()
