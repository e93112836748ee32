"""MuJoCo dynamics shift, online: SAC vs SAC+SRPO vs SAC+ASOR (issue 5), equal env steps.

Every (method, seed) run trains SAC on `rllib_asor/<Task>Shift-v0` with body mass, dof damping
and wind drawn per episode (the tuned examples' setting, tuned_examples/mujoco/), for the same
number of env steps; its deterministic policy is then evaluated under the three fixed dynamics
of the paper's MuJoCo table: `original`, `body_mass` (mass ×3) and `density_10`.

    python -m benchmarks.mujoco_shift --task Hopper --seeds 3 --steps 6000 \
        --out benchmarks/out/mujoco_shift

Methods are `name[:key=value,...]` over AsorConfig fields (`sac` = no ASOR):

    python -m benchmarks.mujoco_shift --methods sac asor:lambda_=0.05 asor_gail:reward_form=gail

Each run is written to OUT/runs/<task>-<method>-<seed>.json as soon as it ends (a rerun skips
finished runs); `--summarize-only` rebuilds OUT/table.md and OUT/summary.json from them.
SAC here uses the tuned examples' settings except the replay/learning-start sizes and the
update-to-data ratio (`--utd`), which are scaled to the budget (flags below).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import mean_std, run_if_missing, start_local_ray

DEFAULT_METHODS = ("sac", "srpo:mode=srpo", "asor:mode=asor")
EVAL_DYNAMICS = ("original", "body_mass", "density_10")
ASOR_BASE = {
    "lambda_": 0.05,
    "rho_value": 0.5,
    "rho_count": 0.5,
    "proxy": "rnd",
    "reward_form": "log",
}


def parse_method(
    text: str, plain: str = "sac", base: dict[str, Any] = ASOR_BASE
) -> tuple[str, dict[str, Any] | None]:
    """`name[:k=v,...]` → (name, `base` updated with k=v; None for the plain algorithm)."""
    name, _, rest = text.partition(":")
    if name == plain and not rest:
        return name, None
    settings: dict[str, Any] = dict(base)
    for item in filter(None, rest.split(",")):
        key, _, value = item.partition("=")
        try:
            settings[key] = json.loads(value)
        except json.JSONDecodeError:
            settings[key] = value
    return name, settings


def sac_config(task: str, seed: int, asor: dict[str, Any] | None, args: argparse.Namespace) -> Any:
    """The shared SAC config (identical for every method), plus ASOR when given."""
    from ray.rllib.algorithms.sac import SACConfig

    import rllib_asor

    # Native ratio with one local env: 256 replayed rows per sampled step; utd·256 per step.
    config = (
        SACConfig()
        .environment(
            f"rllib_asor/{task}Shift-v0", env_config={"params": ["mass", "damping", "wind"]}
        )
        .env_runners(num_env_runners=0, num_envs_per_env_runner=1)
        .training(
            gamma=0.99,
            lr=None,
            actor_lr=3e-4,
            critic_lr=3e-4,
            alpha_lr=3e-4,
            tau=0.005,
            twin_q=True,
            initial_alpha=1.0,
            n_step=1,
            train_batch_size_per_learner=256,
            num_steps_sampled_before_learning_starts=args.learning_starts,
            replay_buffer_config={"type": "EpisodeReplayBuffer", "capacity": 100000},
            training_intensity=args.utd * 256,
        )
        .rl_module(model_config={"fcnet_hiddens": [256, 256], "fcnet_activation": "relu"})
        .reporting(min_sample_timesteps_per_iteration=args.iter_steps)
        .debugging(seed=seed)
    )
    if asor is not None:
        config = rllib_asor.with_asor(config, **({"seed": seed} | asor))
    return config


def deterministic_action(module: Any, obs: np.ndarray) -> np.ndarray:
    """The SAC policy's deterministic (squashed mean) action for one observation."""
    import torch
    from ray.rllib.core import Columns

    with torch.no_grad():
        out = module.forward_inference(
            {Columns.OBS: torch.as_tensor(obs, dtype=torch.float32)[None]}
        )
        dist = module.get_inference_action_dist_cls().from_logits(out[Columns.ACTION_DIST_INPUTS])
        return dist.to_deterministic().sample()[0].numpy()


def evaluate(
    module: Any, task: str, episodes: int, seed: int = 1000
) -> dict[str, dict[str, float]]:
    """Mean return and length of the deterministic policy under each fixed dynamics."""
    import gymnasium as gym

    import rllib_asor.envs  # noqa: F401

    out = {}
    for dyn in EVAL_DYNAMICS:
        env = gym.make(f"rllib_asor/{task}Shift-v0", dynamics=dyn)
        rets, lens = [], []
        for ep in range(episodes):
            obs, _ = env.reset(seed=seed + ep)
            done, ret, n = False, 0.0, 0
            while not done:
                obs, r, term, trunc, _ = env.step(deterministic_action(module, obs))
                ret, n, done = ret + float(r), n + 1, term or trunc
            rets.append(ret)
            lens.append(n)
        env.close()
        out[dyn] = {"return": float(np.mean(rets)), "length": float(np.mean(lens))}
    return out


def train(task: str, seed: int, asor: dict[str, Any] | None, args: argparse.Namespace):
    """Train to `args.steps` env steps; return (algo, curve, last asor stats, wall seconds)."""
    algo = sac_config(task, seed, asor, args).build_algo()
    curve, steps, t0, result = [], 0, time.time(), {}
    while steps < args.steps:
        result = algo.train()
        steps = result["num_env_steps_sampled_lifetime"]
        ret = result["env_runners"].get("episode_return_mean", float("nan"))
        curve.append([int(steps), float(ret)])
        print(
            f"  {task} seed={seed} asor={asor is not None} steps={steps} return={ret:.1f} "
            f"t={time.time() - t0:.0f}s",
            flush=True,
        )
    stats = {k: float(v) for k, v in result.get("asor", {}).items() if np.isscalar(v)}
    return algo, curve, stats, time.time() - t0


def run_one(
    task: str, method: str, seed: int, asor: dict[str, Any] | None, args: argparse.Namespace
) -> dict:
    algo, curve, stats, wall = train(task, seed, asor, args)
    try:
        ev = evaluate(algo.get_module(), task, args.eval_episodes)
    finally:
        algo.stop()
    return {
        "task": task,
        "method": method,
        "asor": asor,
        "seed": seed,
        "steps": curve[-1][0],
        "wall_s": wall,
        "eval": ev,
        "eval_mean": float(np.mean([v["return"] for v in ev.values()])),
        "train_return_last": curve[-1][1],
        "curve": curve,
        "asor_last": stats,
        "settings": {
            k: getattr(args, k) for k in ("steps", "learning_starts", "utd", "iter_steps")
        },
    }


def summarize(out: Path) -> str:
    """Markdown table (mean ± std over seeds) from OUT/runs/*.json."""
    runs = [json.loads(p.read_text()) for p in sorted((out / "runs").glob("*.json"))]
    lines = [
        "| task | method | seeds | env steps | "
        + " | ".join(f"{d} return" for d in EVAL_DYNAMICS)
        + " | mean of the 3 | train return (last iter) | wall s / run |",
        "|---|---|---|---|" + "---|" * len(EVAL_DYNAMICS) + "---|---|---|",
    ]
    table: dict[str, Any] = {}
    keys = sorted({(r["task"], r["method"]) for r in runs}, key=lambda k: (k[0], _order(k[1])))
    for task, method in keys:
        rs = [r for r in runs if r["task"] == task and r["method"] == method]
        per = {d: [r["eval"][d]["return"] for r in rs] for d in EVAL_DYNAMICS}
        means = [r["eval_mean"] for r in rs]
        table[f"{task}/{method}"] = {
            "seeds": [r["seed"] for r in rs],
            "steps": int(np.mean([r["steps"] for r in rs])),
            "eval": {d: {"mean": float(np.mean(v)), "per_seed": v} for d, v in per.items()},
            "eval_mean": float(np.mean(means)),
            "asor_last": [r["asor_last"] for r in rs],
        }
        lines.append(
            f"| {task} | {method} | {len(rs)} | {int(np.mean([r['steps'] for r in rs]))} | "
            + " | ".join(mean_std(per[d]) for d in EVAL_DYNAMICS)
            + f" | {mean_std(means)} | {np.nanmean([r['train_return_last'] for r in rs]):.1f}"
            + f" | {np.mean([r['wall_s'] for r in rs]):.0f} |"
        )
    md = "\n".join(lines) + "\n"
    (out / "table.md").write_text(md)
    (out / "summary.json").write_text(json.dumps(table, indent=1))
    return md


def _order(method: str) -> int:
    return {"sac": 0, "srpo": 1, "asor": 2}.get(method, 3)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument(
        "--tasks", nargs="+", default=["Hopper"], help="Hopper, Walker2d, HalfCheetah, Ant"
    )
    p.add_argument("--methods", nargs="+", default=list(DEFAULT_METHODS))
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--first-seed", type=int, default=0)
    p.add_argument("--steps", type=int, default=6000, help="env steps per run (equal for all)")
    p.add_argument("--learning-starts", type=int, default=1000)
    p.add_argument("--utd", type=float, default=0.25, help="gradient updates per env step")
    p.add_argument("--iter-steps", type=int, default=500, help="env steps per reported iteration")
    p.add_argument("--eval-episodes", type=int, default=2)
    p.add_argument("--out", default="benchmarks/out/mujoco_shift")
    p.add_argument("--summarize-only", action="store_true")
    args = p.parse_args(argv)
    out = Path(args.out)
    if not args.summarize_only:
        import ray

        import rllib_asor.envs  # noqa: F401

        start_local_ray(2)
        (out / "runs").mkdir(parents=True, exist_ok=True)
        # seed-major order: every method gets seed s before any method gets seed s+1
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            for task in args.tasks:
                for text in args.methods:
                    name, asor = parse_method(text)
                    run_if_missing(
                        out / "runs" / f"{task}-{name}-{seed}.json",
                        f"{task} {name} seed {seed}",
                        lambda: run_one(task, name, seed, asor, args),  # noqa: B023 (called at once)
                    )
        ray.shutdown()
    print(summarize(out))


if __name__ == "__main__":
    main()
