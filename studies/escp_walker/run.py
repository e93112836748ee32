"""ESCP vs ESCP+ASOR on Walker2d under gravity shift: a resumable runner.

One independent job per (method, seed), each run saved at once to RUNS/<method>-<seed>.json.gz;
an unfinished run is saved at every evaluation point (RUNS/<method>-<seed>.partial/) and
continued from there; a rerun skips finished runs, so the study resumes where it stopped and several processes (one
per core, different --seeds or --methods) can share one folder. The decision rule and budget
are fixed before any run (studies/escp_walker/README.md names the commit).

Methods (all on `rllib_asor/Walker2dShift-v0`, 40 training tasks of gravity ×1.5^U(-3,3),
task_seed 0, one task per episode):
- `escp`: `EscpConfig()` with ESCP's settings (tuned_examples/mujoco/escp-walker2d.yaml);
- `escp_asor`: `with_asor(EscpConfig(), seed=s)` (the robust default);
- `escp_asor_paper`: `with_asor(EscpConfig(), preset="paper", seed=s)` (the paper's form);
- `sac`: the project's fast SAC (256x256, tuned_examples/mujoco/sac-walker2d.yaml's settings).
Budget scaling (ESCP's own run is 2.4M steps): learning starts after `--learning-starts`
steps and RMDM trains the encoder after `--rmdm-min-replay` steps (ESCP: 20k and 100k).

Evaluation, deterministic (tanh μ, no noise on z), on tasks never trained on:
- stationary: 40 tasks of task_seed 1000, `--eval-episodes` episodes (one task each);
- non-stationary: 16 tasks of task_seed 2000, switching every 100 steps (ESCP's evaluation),
  `--eval-episodes-ns` episodes; every `--eval-every` env steps and at the end.

    cd /work/main && OMP_NUM_THREADS=1 nice -n 5 .venv/bin/python \
        studies/escp_walker/run.py --methods escp escp_asor escp_asor_paper sac \
        --seeds 0 1 2 3 4 --steps 100000
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

ENV_ID = "rllib_asor/Walker2dShift-v0"
TRAIN_ENV = {"params": ["gravity"], "num_tasks": 40, "task_seed": 0}
EVAL_ENVS = {
    "stationary": {"params": ["gravity"], "num_tasks": 40, "task_seed": 1000},
    "ns": {"params": ["gravity"], "num_tasks": 16, "task_seed": 2000, "switch_every": 100},
}
METHODS = ("escp", "escp_asor", "escp_asor_paper", "sac")
HERE = Path(__file__).resolve().parent


def build_config(method: str, seed: int, args: argparse.Namespace) -> Any:
    """The RLlib config of one run."""
    from rllib_asor import EscpConfig, with_asor

    common = {
        "num_steps_sampled_before_learning_starts": args.learning_starts,
        "replay_buffer_config": {"type": "EpisodeReplayBuffer", "capacity": 1_000_000},
    }
    if method == "sac":
        from ray.rllib.algorithms.sac import SACConfig

        from rllib_asor.algorithms.sac.fast import fast_off_policy
        from rllib_asor.data.collect import MUJOCO_SAC_MODEL, MUJOCO_SAC_TRAINING

        cfg = (
            SACConfig()
            .training(**MUJOCO_SAC_TRAINING, **common, target_entropy="auto")
            .rl_module(model_config=MUJOCO_SAC_MODEL)
        )
    else:
        cfg = EscpConfig().training(**common).escp(rmdm_min_replay=args.rmdm_min_replay)
    cfg = (
        cfg.environment(ENV_ID, env_config=TRAIN_ENV)
        .env_runners(num_env_runners=0, num_envs_per_env_runner=1)
        .learners(num_learners=0)
        .reporting(min_sample_timesteps_per_iteration=1000)
        .debugging(seed=seed)
    )
    if method == "sac":
        return fast_off_policy(cfg)
    if method == "escp_asor":
        return with_asor(cfg, seed=seed)
    if method == "escp_asor_paper":
        return with_asor(cfg, preset="paper", seed=seed)
    return cfg


def evaluate(algo: Any, seed: int, args: argparse.Namespace, final: bool) -> dict[str, Any]:
    """Mean return (and per-episode returns) on unseen tasks, stationary and non-stationary."""
    from rllib_asor.algorithms.escp.evaluate import rollout

    module = algo.get_module()
    out = {}
    for name, env in EVAL_ENVS.items():
        n = args.eval_episodes if name == "stationary" else args.eval_episodes_ns
        if not final:
            n = max(2, n // 4)
        res = rollout(module, ENV_ID, n, seed=10_000 + 100 * seed, env_kwargs=env)
        out[name] = {"mean": float(sum(res.returns) / n), "returns": res.returns}
    return out


def run_one(method: str, seed: int, args: argparse.Namespace, partial: Path) -> dict[str, Any]:
    """Train one (method, seed) for `args.steps` env steps with periodic evaluations.

    At every evaluation point the run is saved to `partial` (the algorithm, its replay buffer,
    the curve), and a run found there is continued from it, so a run that is cut off resumes
    at its last evaluation point instead of starting over.
    """
    import pickle

    from studies.lib.common import load_partial, save_partial

    config = build_config(method, seed, args)
    algo = config.build_algo()

    def save(folder: Path) -> None:  # the algorithm and (not in RLlib's checkpoint) its replay
        algo.save_to_path(str(folder / "algo"))
        with open(folder / "replay.pkl", "wb") as f:
            pickle.dump(algo.local_replay_buffer.get_state(), f)

    curve: list[dict[str, Any]] = []
    steps, spent = 0, 0.0
    offset: int | None = 0
    if (found := load_partial(partial)) is not None:
        saved, checkpoint = found
        algo.restore_from_path(str(checkpoint / "algo"))
        with open(checkpoint / "replay.pkl", "rb") as f:
            algo.local_replay_buffer.set_state(pickle.load(f))
        curve, steps, spent = saved["curve"], saved["steps"], saved["train_wall_s"]
        offset = None  # known after the first iteration: did the checkpoint keep the counter?
        print(f"  {method}-{seed}: resumed at {steps} steps", flush=True)
    next_eval = (steps // args.eval_every + 1) * args.eval_every
    t0 = time.time() - spent
    try:
        while steps < args.steps:
            result = algo.train()
            lifetime = int(result["num_env_steps_sampled_lifetime"])
            if offset is None:
                offset = steps if lifetime < steps else 0
            steps = offset + lifetime
            if steps >= next_eval and steps < args.steps:
                curve.append({"steps": steps, **evaluate(algo, seed, args, final=False)})
                next_eval += args.eval_every
                state = {"curve": curve, "steps": steps, "train_wall_s": time.time() - t0}
                save_partial(partial, state, save)
                print(f"  {method}-{seed} {steps} steps, {time.time() - t0:.0f}s", flush=True)
        wall = time.time() - t0
        final = evaluate(algo, seed, args, final=True)
    finally:
        algo.stop()
    return {
        "method": method,
        "seed": seed,
        "steps": steps,
        "train_wall_s": wall,
        "wall_s": time.time() - t0,
        "eval": {k: v["mean"] for k, v in final.items()},
        "final": final,
        "curve": curve,
        "settings": settings(args),
        "resumed": bool(spent),
    }


def settings(args: argparse.Namespace) -> dict[str, Any]:
    """What must match between the runs of one folder."""
    return {
        "steps": args.steps,
        "learning_starts": args.learning_starts,
        "rmdm_min_replay": args.rmdm_min_replay,
        "eval_episodes": args.eval_episodes,
        "eval_episodes_ns": args.eval_episodes_ns,
        "train_env": TRAIN_ENV,
        "eval_envs": EVAL_ENVS,
    }


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS))
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4])
    p.add_argument("--steps", type=int, default=100_000)
    p.add_argument("--learning-starts", type=int, default=5_000)
    p.add_argument("--rmdm-min-replay", type=int, default=25_000)
    p.add_argument("--eval-every", type=int, default=25_000)
    p.add_argument("--eval-episodes", type=int, default=20)
    p.add_argument("--eval-episodes-ns", type=int, default=10)
    p.add_argument("--out", default=str(HERE))
    args = p.parse_args(argv)
    out = Path(args.out)
    (out / "runs").mkdir(parents=True, exist_ok=True)
    from studies.lib.common import start_local_ray
    from studies.lib.run_files import existing, read_run, run_file, write_run

    started = False
    for seed in args.seeds:
        for method in args.methods:
            path = run_file(out / "runs", f"{method}-{seed}")
            if done := existing(path):
                have = read_run(done).get("settings")
                if have != json.loads(json.dumps(settings(args))):
                    raise SystemExit(f"{done} was made with other settings: {have}")
                continue
            if not started:
                start_local_ray()
                started = True
            print(f"run {method}-{seed} ({os.getpid()})", flush=True)
            partial = out / "runs" / f"{method}-{seed}.partial"
            res = run_one(method, seed, args, partial)
            write_run(path, res)
            shutil.rmtree(partial, ignore_errors=True)
            print(f"  {method}-{seed} eval {res['eval']} wall {res['wall_s']:.0f}s", flush=True)


if __name__ == "__main__":
    main()
