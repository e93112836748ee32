"""Traffic density, online: PPO vs PPO+ASOR on `rllib_asor/HighwayDensity-v0`.

Density d is drawn per episode from {0.5, 1, 1.5, 2} (base_vehicles_count 10, the tuned
examples' laptop setting, tuned_examples/highway/). Every run trains for the same number of
env steps; its greedy policy is then evaluated at fixed densities (return, crash rate, mean
speed). highway-env costs 35-175 ms per decision on one core, so the budget is tiny.

    python -m studies.lib.traffic_density --seeds 1 --steps 1500 --out studies/out/traffic_density

Runs are written to OUT/runs/<method>-<seed>.json.gz as they end (a rerun skips them);
`--summarize-only` rebuilds OUT/table.md and OUT/summary.json.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from studies.lib.common import round_floats, run_if_missing, start_local_ray
from studies.lib.run_files import read_runs, run_file

METHODS = {
    "ppo": None,
    "asor": {
        "preset": "paper",  # the form these results were measured with
        "mode": "asor",
        "proxy": "rnd",
        "rho_value": 0.5,
        "rho_count": 0.5,
        "lambda_": 0.01,
        "reward_form": "log",
    },
}
ENV_CONFIG = {"densities": [0.5, 1.0, 1.5, 2.0], "base_vehicles_count": 10}


def ppo_config(seed: int, asor: dict[str, Any] | None, args: argparse.Namespace) -> Any:
    """The shared PPO config (tuned_examples/highway/ppo.yaml, batch scaled to the budget)."""
    from ray.rllib.algorithms.ppo import PPOConfig

    import rllib_asor

    config = (
        PPOConfig()
        .environment("rllib_asor/HighwayDensity-v0", env_config=ENV_CONFIG)
        .env_runners(num_env_runners=0, num_envs_per_env_runner=1)
        .training(
            gamma=0.8,
            lambda_=0.95,
            lr=5e-4,
            entropy_coeff=0.0,
            train_batch_size=args.batch,
            minibatch_size=64,
            num_epochs=10,
        )
        .rl_module(model_config={"fcnet_hiddens": [256, 256]})
        .debugging(seed=seed)
    )
    if asor is not None:
        config = rllib_asor.with_asor(config, **({"seed": seed} | asor))
    return config


def evaluate(module: Any, densities: list[float], episodes: int) -> dict[str, dict[str, float]]:
    """Greedy policy at fixed densities: mean return, crash rate, mean speed (m/s)."""
    from rllib_asor.evaluation.rollout import module_actor, rollout, to_int

    out = {}
    for d in densities:
        speeds: list[float] = []
        done = rollout(
            module_actor(module), "rllib_asor/HighwayDensity-v0", episodes, seed=2000,
            env_kwargs={**ENV_CONFIG, "densities": [d]}, action_fn=to_int,
            watch=lambda ep, a, r, info, speeds=speeds: speeds.append(info.get("speed", np.nan)),
        )  # fmt: skip
        crashes = [float(bool(ep.info.get("crashed", False))) for ep in done.episodes]
        out[str(d)] = {
            "return": float(np.mean(done.returns)),
            "crash_rate": float(np.mean(crashes)),
            "speed": float(np.nanmean(np.asarray(speeds, dtype=float))),
        }
    return out


def run_one(method: str, seed: int, args: argparse.Namespace) -> dict[str, Any]:
    asor = METHODS[method]
    algo = ppo_config(seed, asor, args).build_algo()
    curve, steps, t0, result = [], 0, time.time(), {}
    try:
        while steps < args.steps:
            result = algo.train()
            steps = result["num_env_steps_sampled_lifetime"]
            ret = result["env_runners"].get("episode_return_mean", float("nan"))
            curve.append([int(steps), float(ret)])
            print(
                f"  {method} seed={seed} steps={steps} return={ret:.2f} t={time.time() - t0:.0f}s",
                flush=True,
            )
        wall = time.time() - t0
        ev = evaluate(algo.get_module(), args.eval_densities, args.eval_episodes)
    finally:
        algo.stop()
    return {
        "method": method,
        "seed": seed,
        "steps": curve[-1][0],
        "wall_s": wall,
        "eval": ev,
        "eval_return_mean": float(np.mean([v["return"] for v in ev.values()])),
        "train_return_last": curve[-1][1],
        "curve": round_floats(curve),
        "asor_last": {k: float(v) for k, v in result.get("asor", {}).items() if np.isscalar(v)},
        "settings": {"steps": args.steps, "batch": args.batch, "eval_episodes": args.eval_episodes},
    }


def summarize(out: Path, densities: list[float]) -> str:
    runs = read_runs(out / "runs")
    ds = [str(d) for d in densities]
    lines = [
        "| method | seeds | env steps | "
        + " | ".join(f"d={d}: return / crash rate" for d in ds)
        + " | train return (last iter) | wall s / run |",
        "|---|---|---|" + "---|" * len(ds) + "---|---|",
    ]
    table = {}
    for method in METHODS:
        rs = [r for r in runs if r["method"] == method]
        if not rs:
            continue
        per = {
            d: ([r["eval"][d]["return"] for r in rs], [r["eval"][d]["crash_rate"] for r in rs])
            for d in ds
            if all(d in r["eval"] for r in rs)
        }
        table[method] = {
            "seeds": [r["seed"] for r in rs],
            "eval": {
                d: {"return": float(np.mean(a)), "crash_rate": float(np.mean(b))}
                for d, (a, b) in per.items()
            },
            "asor_last": [r["asor_last"] for r in rs],
        }
        lines.append(
            f"| {method} | {len(rs)} | {int(np.mean([r['steps'] for r in rs]))} | "
            + " | ".join(f"{np.mean(per[d][0]):.2f} / {np.mean(per[d][1]):.2f}" for d in per)
            + f" | {np.nanmean([r['train_return_last'] for r in rs]):.2f}"
            + f" | {np.mean([r['wall_s'] for r in rs]):.0f} |"
        )
    md = "\n".join(lines) + "\n"
    (out / "table.md").write_text(md)
    (out / "summary.json").write_text(json.dumps(table, indent=1))
    return md


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--methods", nargs="+", default=list(METHODS), choices=list(METHODS))
    p.add_argument("--seeds", type=int, default=1)
    p.add_argument("--steps", type=int, default=1500, help="env steps per run (equal for all)")
    p.add_argument("--batch", type=int, default=500, help="PPO train_batch_size")
    p.add_argument("--eval-densities", type=float, nargs="+", default=[0.5, 1.0, 2.0])
    p.add_argument("--eval-episodes", type=int, default=3)
    p.add_argument("--out", default="studies/out/traffic_density")
    p.add_argument("--summarize-only", action="store_true")
    args = p.parse_args(argv)
    out = Path(args.out)
    if not args.summarize_only:
        import ray

        import rllib_asor.envs  # noqa: F401  (registers the env ids for the local env runner)

        start_local_ray(2)
        (out / "runs").mkdir(parents=True, exist_ok=True)
        for seed in range(args.seeds):
            for method in args.methods:
                run_if_missing(
                    run_file(out / "runs", f"{method}-{seed}"),
                    f"{method} seed {seed}",
                    lambda: run_one(method, seed, args),  # noqa: B023 (called at once)
                )
        ray.shutdown()
    print(summarize(out, args.eval_densities))


if __name__ == "__main__":
    main()
