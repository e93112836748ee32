"""MuJoCo dynamics shift, online: SAC or PPO, each vs +SRPO vs +ASOR, equal env steps.

Every (method, seed) run trains SAC (`--algo sac`, default) or PPO (`--algo ppo`) on
`rllib_asor/<Task>Shift-v0` with body mass, dof damping and wind drawn per episode (the tuned
examples' setting, tuned_examples/mujoco/), for the same number of env steps; its deterministic
policy is then evaluated under the three fixed dynamics of the paper's MuJoCo table: `original`,
`body_mass` (mass ×3) and `density_10`.

    python -m studies.lib.mujoco_shift --task Hopper --seeds 3 --steps 6000 \
        --out studies/out/mujoco_shift
    python -m studies.lib.mujoco_shift --algo ppo --task Hopper --seeds 5 --steps 300000 \
        --methods ppo asor:mode=asor --out studies/out/mujoco_shift_ppo

Methods are `name[:key=value,...]`; the plain algorithm's name (`sac` or `ppo`) means no ASOR,
any other name is ASOR with exactly the AsorConfig fields it names (nothing is merged in, so
`asor:mode=asor` is `with_asor`'s default, the robust preset). The short SAC table (docs/results.md)
spelled its settings out:

    --methods sac \
        srpo:preset=paper,mode=srpo,lambda_=0.05,rho_value=0.5,rho_count=0.5,proxy=rnd,reward_form=log \
        asor:preset=paper,mode=asor,lambda_=0.05,rho_value=0.5,rho_count=0.5,proxy=rnd,reward_form=log

Each run is written to OUT/runs/<task>-<method>-<seed>.json.gz (SAC, the old names) or
OUT/runs/<task>-ppo-<method>-<seed>.json.gz (PPO; `studies.lib.run_files`) as soon as it ends
(a rerun skips finished runs); `--summarize-only` rebuilds OUT/table.md and OUT/summary.json
from them, one table per algo.
A run file holds `eval` (per dynamics), `eval_return_mean` (mean return over the three),
`curve` ([env steps, training episode return] per iteration) and `asor_last` (the last
iteration's `result["asor"]`). studies.lib.compare reads (method, seed) only, so give each algo
its own OUT for it: `python -m studies.lib.compare --runs OUT --metric eval_return_mean
--baseline ppo`.

SAC here uses the tuned examples' settings except the replay/learning-start sizes and the
update-to-data ratio (`--utd`), which are scaled to the budget (flags below). PPO uses the usual
MuJoCo settings (Schulman et al. 2017 / CleanRL): 8 vectorised envs on the local env runner,
2048 env steps per iteration, 10 epochs of minibatch `--minibatch` (default 64), lr 3e-4,
γ 0.99, GAE λ 0.95, clip 0.2, separate 64-64 tanh policy and value MLPs, no entropy bonus,
observations normalised by RLlib's MeanStdFilter connector (evaluation uses its frozen stats);
RLlib's defaults otherwise (vf_loss_coeff 1, adaptive KL penalty), except vf_clip_param 1e4
(RLlib's 10 would clip the value loss at Hopper's return scale).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from studies.lib.common import mean_std, round_floats, run_if_missing, start_local_ray
from studies.lib.run_files import read_runs, run_file

DEFAULT_METHODS = {
    "sac": ("sac", "srpo:mode=srpo", "asor:mode=asor"),
    "ppo": ("ppo", "srpo:mode=srpo", "asor:mode=asor"),
}
EVAL_DYNAMICS = ("original", "body_mass", "density_10")


def parse_method(
    text: str, plain: str = "sac", base: dict[str, Any] | None = None
) -> tuple[str, dict[str, Any] | None]:
    """`name[:k=v,...]` → (name, {k: v} as AsorConfig fields; None for the plain algorithm).

    Values are JSON where they parse (`0.05`, `true`, `[64, 64]`), else strings. `base` (none
    here; studies.lib.offline_cql passes its own) is updated with k=v."""
    name, _, rest = text.partition(":")
    if name == plain and not rest:
        return name, None
    settings: dict[str, Any] = dict(base or {})
    for item in filter(None, rest.split(",")):
        key, _, value = item.partition("=")
        try:
            settings[key] = json.loads(value)
        except json.JSONDecodeError:
            settings[key] = value
    return name, settings


def sac_config(task: str, seed: int, asor: dict[str, Any] | None, args: argparse.Namespace) -> Any:
    """The shared SAC config (identical for every method: the fast off-policy path,
    `FastSACConfig`), plus ASOR when given."""
    import rllib_asor
    from rllib_asor.data.collect import MUJOCO_SAC_MODEL, MUJOCO_SAC_TRAINING

    # Native ratio with one local env: 256 replayed rows per sampled step; utd·256 per step.
    config = (
        rllib_asor.FastSACConfig()
        .environment(
            f"rllib_asor/{task}Shift-v0", env_config={"params": ["mass", "damping", "wind"]}
        )
        .env_runners(num_env_runners=0, num_envs_per_env_runner=1)
        .training(
            **MUJOCO_SAC_TRAINING,
            num_steps_sampled_before_learning_starts=args.learning_starts,
            replay_buffer_config={"type": "EpisodeReplayBuffer", "capacity": 100000},
            training_intensity=args.utd * 256,
        )
        .rl_module(model_config=MUJOCO_SAC_MODEL)
        .reporting(min_sample_timesteps_per_iteration=args.iter_steps)
        .debugging(seed=seed)
    )
    if asor is not None:
        config = rllib_asor.with_asor(config, **({"seed": seed} | asor))
    return config


def ppo_config(task: str, seed: int, asor: dict[str, Any] | None, args: argparse.Namespace) -> Any:
    """The shared PPO config (identical for every method), plus ASOR when given."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.connectors.env_to_module import MeanStdFilter

    import rllib_asor
    from rllib_asor.data.collect import MUJOCO_PPO_MODEL, MUJOCO_PPO_TRAINING

    config = (
        PPOConfig()
        .environment(
            f"rllib_asor/{task}Shift-v0", env_config={"params": ["mass", "damping", "wind"]}
        )
        .env_runners(
            num_env_runners=0,
            num_envs_per_env_runner=8,
            env_to_module_connector=lambda env, spaces, device: MeanStdFilter(),
        )
        .learners(num_learners=0)
        .training(
            train_batch_size_per_learner=2048, minibatch_size=args.minibatch, **MUJOCO_PPO_TRAINING
        )
        .rl_module(model_config=dict(MUJOCO_PPO_MODEL))
        .debugging(seed=seed)
    )
    if asor is not None:
        config = rllib_asor.with_asor(config, **({"seed": seed} | asor))
    return config


CONFIGS = {"sac": sac_config, "ppo": ppo_config}


def obs_filter(algo: Any) -> Any:
    """The local env runner's observation normaliser with frozen stats (identity if none)."""
    from ray.rllib.connectors.env_to_module import MeanStdFilter

    pipeline = getattr(algo.env_runner, "_env_to_module", None)
    for piece in getattr(pipeline, "connectors", []):
        if isinstance(piece, MeanStdFilter) and piece._filters is not None:
            filt = piece._filters[None]
            return lambda obs: filt(obs, update=False)
    return lambda obs: obs


def evaluate(
    module: Any, task: str, episodes: int, seed: int = 1000, obs_fn: Any = None
) -> dict[str, dict[str, float]]:
    """Mean return and length of the deterministic policy under each fixed dynamics (actions
    clipped to the action space, as RLlib's env runner does; `obs_fn` normalises obs)."""
    from rllib_asor.evaluation.rollout import clip, module_actor, rollout

    out = {}
    for dyn in EVAL_DYNAMICS:
        done = rollout(
            module_actor(module, obs_fn), f"rllib_asor/{task}Shift-v0", episodes, seed=seed,
            env_kwargs={"dynamics": dyn}, action_fn=clip,
        )  # fmt: skip
        out[dyn] = {"return": float(np.mean(done.returns)), "length": float(np.mean(done.lengths))}
    return out


def train(task: str, seed: int, asor: dict[str, Any] | None, args: argparse.Namespace):
    """Train to `args.steps` env steps; return (algo, curve, last asor stats, wall seconds)."""
    algo_name = getattr(args, "algo", "sac")  # studies.lib.walker_figure's args have no algo
    algo = CONFIGS[algo_name](task, seed, asor, args).build_algo()
    curve, steps, t0, result = [], 0, time.time(), {}
    while steps < args.steps:
        result = algo.train()
        steps = result["num_env_steps_sampled_lifetime"]
        ret = result["env_runners"].get("episode_return_mean", float("nan"))
        curve.append([int(steps), float(ret)])
        print(
            f"  {task} {algo_name} seed={seed} asor={asor is not None} steps={steps} "
            f"return={ret:.1f} "
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
        ev = evaluate(algo.get_module(), task, args.eval_episodes, obs_fn=obs_filter(algo))
    finally:
        algo.stop()
    eval_mean = float(np.mean([v["return"] for v in ev.values()]))
    sac_keys = ("steps", "learning_starts", "utd", "iter_steps")
    keys = sac_keys if args.algo == "sac" else ("steps", "minibatch")
    return {
        "algo": args.algo,
        "task": task,
        "method": method,
        "asor": asor,
        "seed": seed,
        "steps": curve[-1][0],
        "wall_s": wall,
        "eval": ev,
        "eval_mean": eval_mean,
        "eval_return_mean": eval_mean,
        "train_return_last": curve[-1][1],
        "curve": round_floats(curve),
        "asor_last": stats,
        "settings": {k: getattr(args, k) for k in keys},
    }


def summarize(out: Path) -> str:
    """Markdown table per algo (mean ± std over seeds) from OUT/runs/ (a run file without
    `algo` is SAC). With SAC runs only, one table."""
    runs = read_runs(out / "runs")
    algos = sorted({r.get("algo", "sac") for r in runs}, key=lambda a: (a != "sac", a))
    table: dict[str, Any] = {}
    parts = []
    for algo in algos:
        lines = [
            "| task | method | seeds | env steps | "
            + " | ".join(f"{d} return" for d in EVAL_DYNAMICS)
            + " | mean of the 3 | train return (last iter) | wall s / run |",
            "|---|---|---|---|" + "---|" * len(EVAL_DYNAMICS) + "---|---|---|",
        ]
        mine = [r for r in runs if r.get("algo", "sac") == algo]
        keys = sorted({(r["task"], r["method"]) for r in mine}, key=lambda k: (k[0], _order(k[1])))
        for task, method in keys:
            rs = [r for r in mine if r["task"] == task and r["method"] == method]
            per = {d: [r["eval"][d]["return"] for r in rs] for d in EVAL_DYNAMICS}
            means = [r["eval_mean"] for r in rs]
            key = f"{task}/{method}" if algo == "sac" else f"{algo}/{task}/{method}"
            table[key] = {
                "algo": algo,
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
        head = f"**{algo}**\n\n" if len(algos) > 1 else ""
        parts.append(head + "\n".join(lines) + "\n")
    md = "\n".join(parts)
    (out / "table.md").write_text(md)
    (out / "summary.json").write_text(json.dumps(table, indent=1))
    return md


def run_path(out: Path, algo: str, task: str, method: str, seed: int) -> Path:
    """The run file OUT/runs/<task>-<method>-<seed> (SAC, as before) or
    <task>-<algo>-<method>-<seed> (`run_files.run_file`)."""
    stem = f"{task}-{method}-{seed}" if algo == "sac" else f"{task}-{algo}-{method}-{seed}"
    return run_file(out / "runs", stem)


def _order(method: str) -> int:
    return {"sac": 0, "ppo": 0, "srpo": 1, "asor": 2}.get(method, 3)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument(
        "--tasks", nargs="+", default=["Hopper"], help="Hopper, Walker2d, HalfCheetah, Ant"
    )
    p.add_argument("--algo", choices=sorted(CONFIGS), default="sac")
    p.add_argument(
        "--methods", nargs="+", default=None, help="default: <algo> srpo:mode=srpo asor:mode=asor"
    )
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--first-seed", type=int, default=0)
    p.add_argument("--steps", type=int, default=6000, help="env steps per run (equal for all)")
    p.add_argument("--learning-starts", type=int, default=1000)
    p.add_argument("--utd", type=float, default=0.25, help="gradient updates per env step")
    p.add_argument("--iter-steps", type=int, default=500, help="env steps per reported iteration")
    p.add_argument("--minibatch", type=int, default=64, help="PPO minibatch size")
    p.add_argument("--eval-episodes", type=int, default=2)
    p.add_argument("--out", default="studies/out/mujoco_shift")
    p.add_argument("--summarize-only", action="store_true")
    args = p.parse_args(argv)
    methods = [parse_method(t, plain=args.algo) for t in args.methods or DEFAULT_METHODS[args.algo]]
    for name, _ in methods:
        # "ppo…" SAC names could collide with PPO run files, another algo's name is no ASOR method
        if (name in CONFIGS and name != args.algo) or (args.algo == "sac" and name[:4] == "ppo-"):
            p.error(f"method name {name!r} is reserved with --algo {args.algo}")
    out = Path(args.out)
    if not args.summarize_only:
        import ray

        import rllib_asor.envs  # noqa: F401

        start_local_ray(2)
        (out / "runs").mkdir(parents=True, exist_ok=True)
        # seed-major order: every method gets seed s before any method gets seed s+1
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            for task in args.tasks:
                for name, asor in methods:
                    run_if_missing(
                        run_path(out, args.algo, task, name, seed),
                        f"{task} {args.algo} {name} seed {seed}",
                        lambda: run_one(task, name, seed, asor, args),  # noqa: B023 (called at once)
                    )
        ray.shutdown()
    print(summarize(out))


if __name__ == "__main__":
    main()
