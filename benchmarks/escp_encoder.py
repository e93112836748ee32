"""Does ESCP's encoder do its job?

1. **Tasks separate on held-out episodes.** After training, deterministic episodes (not in the
   replay buffer) on each of K training tasks; z at every step with a full window (t ≥ H).
   Per task the mean z of half the episodes is the reference; the other half's steps are
   classified by the nearest reference mean. Accuracy vs the same classifier after shuffling
   the task labels of the reference half (chance ≈ 1/K), over `--shuffles` shuffles.
2. **Sudden switch.** Episodes whose task switches every 100 steps between two training tasks
   (ESCP's non-stationary evaluation); after each switch, the steps until z is nearer to the
   new task's reference mean than to the old one's (the window is H = 16 steps).
3. A figure: z by task (held-out) and z through switches, docs/figures/escp_z.png.

Trains ESCP first (or loads `--checkpoint`). Default: HalfCheetah, dof damping ×1.5^U(-3,3),
8 tasks, a short run (the encoder's RMDM needs only diverse data, not a good policy):

    OMP_NUM_THREADS=1 nice -n 5 .venv/bin/python -m benchmarks.escp_encoder \
        --steps 12000 --out benchmarks/out/escp_encoder --figure docs/figures/escp_z.png
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import start_local_ray, write_json

ENV_ID = "rllib_asor/HalfCheetahShift-v0"


def train(args: argparse.Namespace) -> Any:
    from rllib_asor import EscpConfig

    cfg = (
        EscpConfig()
        .environment(ENV_ID, env_config=env_config(args))
        .env_runners(num_env_runners=0)
        .training(num_steps_sampled_before_learning_starts=args.learning_starts)
        .escp(num_tasks=args.tasks, rmdm_min_replay=args.learning_starts)
        .reporting(min_sample_timesteps_per_iteration=1000)
        .debugging(seed=args.seed)
    )
    algo = cfg.build_algo()
    if args.checkpoint:
        algo.restore_from_path(args.checkpoint)
        return algo
    steps, t0 = 0, time.time()
    while steps < args.steps:
        steps = int(algo.train()["num_env_steps_sampled_lifetime"])
        print(f"trained {steps} steps in {time.time() - t0:.0f}s", flush=True)
    algo.save_to_path(str(Path(args.out).resolve() / "checkpoint"))  # --checkpoint reuses it
    return algo


def env_config(args: argparse.Namespace, **extra: Any) -> dict[str, Any]:
    return {
        "params": ["damping"],
        "num_tasks": args.tasks,
        "task_seed": 0,
        "max_episode_steps": args.episode_steps,
        **extra,
    }


def task_episodes(module: Any, args: argparse.Namespace) -> tuple[np.ndarray, ...]:
    """z [N, d], task ids [N] and episode halves [N] of held-out deterministic episodes (steps t ≥ H)."""
    import gymnasium as gym

    env = gym.make(ENV_ID, **env_config(args))
    pool = env.unwrapped.tasks
    env.close()
    zs, ids, halves = [], [], []
    h = module.escp.history_len
    for task in range(args.tasks):
        kw = env_config(args)  # the training pool's task, set exactly through reset options
        for ep in range(args.episodes_per_task):
            res = _one_task_rollout(module, pool[task], kw, seed=1000 * task + ep)
            z = res[h:]
            zs.append(z)
            ids.append(np.full(len(z), task))
            halves.append(np.full(len(z), ep % 2))
    return np.concatenate(zs), np.concatenate(ids), np.concatenate(halves)


def _one_task_rollout(module: Any, values: dict, kw: dict, seed: int) -> np.ndarray:
    """z along one deterministic episode under fixed dynamics `values`."""
    from rllib_asor.algorithms.escp.evaluate import rollout

    env_kwargs = {k: v for k, v in kw.items() if k not in ("num_tasks",)}
    res = rollout(
        module, ENV_ID, 1, seed=seed, env_kwargs=env_kwargs, record_context=True,
        reset_options={"dynamics": values},
    )  # fmt: skip
    return res.contexts[0]


def nearest_mean_accuracy(z, ids, halves, rng=None) -> float:
    """Fit per-task means on half 0 (labels optionally permuted), classify half 1."""
    ref, test = halves == 0, halves == 1
    labels = ids[ref] if rng is None else rng.permutation(ids[ref])
    tasks = np.unique(ids)
    means = np.stack([z[ref][labels == t].mean(0) for t in tasks])
    pred = tasks[np.argmin(((z[test][:, None] - means[None]) ** 2).sum(-1), axis=1)]
    return float((pred == ids[test]).mean())


def switch_lags(module: Any, means: np.ndarray, args: argparse.Namespace) -> dict[str, Any]:
    """Steps after each switch until z is nearer the new task's mean than the old one's."""
    import gymnasium as gym

    # the two most separated tasks, alternating every 100 steps (a 2-task pool)
    d = ((means[:, None] - means[None]) ** 2).sum(-1)
    a, b = np.unravel_index(np.argmax(d), d.shape)
    env = gym.make(ENV_ID, **env_config(args))
    pool = env.unwrapped.tasks
    env.close()
    lags, trace = [], None
    for ep in range(args.switch_episodes):
        kw = env_config(args, switch_every=100)
        z, seq = _switching_rollout(module, [pool[a], pool[b]], kw, seed=5000 + ep)
        trace = trace or {"z": z.tolist(), "task": seq.tolist(), "tasks": [int(a), int(b)]}
        for s in range(100, len(z), 100):
            new, old = (a, b) if seq[s] == 0 else (b, a)
            closer = ((z[s:] - means[new]) ** 2).sum(-1) < ((z[s:] - means[old]) ** 2).sum(-1)
            hit = np.flatnonzero(closer[: min(100, len(z) - s)])
            lags.append(int(hit[0]) if len(hit) else 100)
    return {
        "lags": lags,
        "median_lag": float(np.median(lags)) if lags else float("nan"),
        "within_window": float(np.mean(np.array(lags) <= 16)) if lags else float("nan"),
        "trace": trace,
    }


def _switching_rollout(module, values: list[dict], kw: dict, seed: int):
    """z along one episode whose dynamics alternate values[0], values[1] every 100 steps."""
    import itertools

    import gymnasium as gym

    from rllib_asor.algorithms.escp.evaluate import EscpActor
    from rllib_asor.evaluation.rollout import rollout, unsquash

    env = gym.make(
        ENV_ID, **{k: v for k, v in kw.items() if k not in ("num_tasks", "switch_every")}
    )
    actor, seq = EscpActor(module, record_context=True), []

    def switching():  # ESCP's step, switching the env's dynamics every 100 steps
        step, steps = actor(), itertools.count()

        def switch(obs, info):
            t = next(steps)
            seq.append((t // 100) % 2 if t > 0 else 0)
            if t > 0 and t % 100 == 0:
                env.unwrapped.set_dynamics(values[(t // 100) % 2])
            return step(obs, info)

        return switch

    try:
        rollout(
            switching, env, 1, seed=seed, action_fn=unsquash,
            reset_options={"dynamics": values[0]},
        )  # fmt: skip
    finally:
        env.close()
    return np.asarray(actor.contexts[0]), np.asarray(seq)


def figure(z, ids, halves, trace, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    for t in np.unique(ids):
        m = (ids == t) & (halves == 1)
        ax[0].scatter(z[m, 0], z[m, 1], s=3, alpha=0.4, label=f"task {t}")
    ax[0].set(xlabel="z[0]", ylabel="z[1]", title="ESCP's z on held-out episodes, by task")
    ax[0].legend(markerscale=4, fontsize=7, ncol=2)
    zt = np.asarray(trace["z"])
    ax[1].plot(zt[:, 0], label="z[0]")
    ax[1].plot(zt[:, 1], label="z[1]")
    for s in range(100, len(zt), 100):
        ax[1].axvline(s, color="k", ls="--", alpha=0.2)
    ax[1].set(xlabel="step", title=f"z through switches (tasks {trace['tasks']}, every 100 steps)")
    ax[1].legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--steps", type=int, default=12_000)
    p.add_argument("--learning-starts", type=int, default=2_000)
    p.add_argument("--tasks", type=int, default=8)
    p.add_argument("--episode-steps", type=int, default=300)
    p.add_argument("--episodes-per-task", type=int, default=4)
    p.add_argument("--switch-episodes", type=int, default=2)
    p.add_argument("--shuffles", type=int, default=200)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--checkpoint", default=None)
    p.add_argument("--out", default="benchmarks/out/escp_encoder")
    p.add_argument("--figure", default="docs/figures/escp_z.png")
    args = p.parse_args(argv)
    start_local_ray()
    algo = train(args)
    module = algo.get_module().unwrapped()
    z, ids, halves = task_episodes(module, args)
    acc = nearest_mean_accuracy(z, ids, halves)
    rng = np.random.default_rng(args.seed)
    shuffled = [nearest_mean_accuracy(z, ids, halves, rng) for _ in range(args.shuffles)]
    tasks = np.unique(ids)
    means = np.stack([z[(ids == t) & (halves == 0)].mean(0) for t in tasks])
    sw = switch_lags(module, means, args)
    algo.stop()
    res = {
        "settings": vars(args),
        "accuracy": acc,
        "shuffled_mean": float(np.mean(shuffled)),
        "shuffled_p95": float(np.quantile(shuffled, 0.95)),
        "p_value": float((1 + sum(s >= acc for s in shuffled)) / (1 + len(shuffled))),
        "chance": 1.0 / len(tasks),
        "steps_scored": int(len(z)),
        "switch": {k: v for k, v in sw.items() if k != "trace"},
    }
    write_json(Path(args.out) / "escp_encoder.json", {**res, "trace": sw["trace"]})
    figure(z, ids, halves, sw["trace"], Path(args.figure))
    print({k: v for k, v in res.items() if k != "settings"})


if __name__ == "__main__":
    main()
