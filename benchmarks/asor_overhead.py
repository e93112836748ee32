"""ASOR's cost: env steps trained per second, PPO vs PPO+ASOR on the same config, one run.

The two algorithms are built side by side and their iterations interleaved (PPO, ASOR, PPO,
...), so machine noise hits both alike; the first iterations (warm-up) are dropped. The
throughput of an iteration is its env steps / `time_this_iter_s`.

    python -m benchmarks.asor_overhead --iters 12 --out benchmarks/out/overhead
    python -m benchmarks.asor_overhead --env game_env/ObstacleRace-v0 --env-runners 2
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import start_local_ray

TARGET = 0.85
"""PPO+ASOR ÷ PPO env steps/s on the lava world (the ratio of the medians): ASOR's cost target."""


def build(env: str, asor: bool, args: argparse.Namespace) -> Any:
    """The benchmark's PPO (or PPO+ASOR) algorithm."""
    from ray.rllib.algorithms.ppo import PPOConfig

    import rllib_asor

    if env.startswith("game_env/"):
        from rllib_asor.race.config import RACE_ASOR_OBS_KEYS, race_ppo_config

        config = race_ppo_config(num_racers=1)
        extra = {"obs_keys": list(RACE_ASOR_OBS_KEYS)}
    else:
        config = PPOConfig().environment(env).rl_module(model_config={"fcnet_hiddens": [64, 64]})
        extra = {}
    config = (
        config.env_runners(
            num_env_runners=args.env_runners,
            num_envs_per_env_runner=args.envs_per_runner,
            num_cpus_per_env_runner=0.5,
        )
        .training(train_batch_size=args.batch, minibatch_size=256, num_epochs=args.epochs)
        .debugging(seed=0)
    )
    if asor:
        config = rllib_asor.with_asor(config, **({"lambda_": 0.01} | extra | args.asor))
    return config.build_algo()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--env", default="rllib_asor/LavaWorld-v0")
    parser.add_argument("--iters", type=int, default=12)
    parser.add_argument("--warmup", type=int, default=2)
    parser.add_argument("--env-runners", type=int, default=0)
    parser.add_argument("--envs-per-runner", type=int, default=8)
    parser.add_argument("--batch", type=int, default=2000)
    parser.add_argument("--epochs", type=int, default=6)
    parser.add_argument("--asor", type=json.loads, default={}, help="JSON of extra ASOR settings")
    parser.add_argument("--out", default="benchmarks/out/overhead")
    args = parser.parse_args(argv)


    import rllib_asor.envs  # noqa: F401

    start_local_ray(4)
    from rllib_asor.registry.env_names import register_env

    register_env(args.env)  # remote env runners build our ids through Tune's registry
    algos = {"PPO": build(args.env, False, args), "PPO+ASOR": build(args.env, True, args)}
    rates: dict[str, list[float]] = {k: [] for k in algos}
    for i in range(args.iters):
        for name, algo in algos.items():
            r = algo.train()
            steps = r["env_runners"]["num_env_steps_sampled"]
            if i >= args.warmup:
                rates[name].append(steps / r["time_this_iter_s"])
    for algo in algos.values():
        algo.stop()
    med = {k: float(np.median(v)) for k, v in rates.items()}
    ratio = med["PPO+ASOR"] / med["PPO"]
    # Paired ratio per iteration pair: robust to slow drifts of machine load.
    paired = np.array(rates["PPO+ASOR"]) / np.array(rates["PPO"])
    summary = {
        "env": args.env,
        "env_runners": args.env_runners,
        "batch": args.batch,
        "epochs": args.epochs,
        "iters_measured": args.iters - args.warmup,
        "steps_per_s_median": med,
        "ratio_of_medians": ratio,
        "paired_ratio_median": float(np.median(paired)),
        "target": TARGET,
        "rates": rates,
    }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tag = f"{args.env.replace('/', '_')}-r{args.env_runners}"
    (out / f"{tag}.json").write_text(json.dumps(summary, indent=1))
    md = (
        "| env | env runners | PPO steps/s | PPO+ASOR steps/s | ratio (medians) | paired ratio | target |\n"
        "|---|---|---|---|---|---|---|\n"
        f"| {args.env} | {args.env_runners} | {med['PPO']:.0f} | {med['PPO+ASOR']:.0f} | {ratio:.2f} | "
        f"{np.median(paired):.2f} | ≥ {TARGET} |\n"
    )
    (out / f"{tag}.md").write_text(md)
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
