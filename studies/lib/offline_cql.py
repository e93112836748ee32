"""Offline cross-dynamics RL: CQL vs CQL+SRPO vs CQL+ASOR on our D4RL-like datasets.

Every (method, seed) run trains CQL (tuned_examples/offline/ settings) on one dataset quality
mixed over the three dynamics (`original`, `body_mass`, `density_10`: the paper's offline
setting) for the same number of gradient updates, then scores the deterministic policy under
each dynamics with D4RL's normalised score against the dataset's own random and expert
returns (`rllib_asor.data.scoring.evaluate`).

    make datasets                          # or: rllib data collect ...
    python -m studies.lib.offline_cql --data data/offline/hopper --quality medium --seeds 3 \\
        --iters 20 --iter-updates 100 --out studies/out/offline_cql

Methods are `name[:key=value,...]` over AsorConfig fields (`cql` = no ASOR), as in
`studies.lib.mujoco_shift`. Runs are written to OUT/runs/<quality>-<method>-<seed>.json.gz as they
end (a rerun skips them); `--summarize-only` rebuilds OUT/table.md and OUT/summary.json.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from studies.lib.common import mean_std, run_if_missing, start_local_ray
from studies.lib.compare import sign_rule
from studies.lib.mujoco_shift import parse_method
from studies.lib.run_files import read_runs, run_file

DEFAULT_METHODS = ("cql", "srpo:mode=srpo", "asor:mode=asor")
MARGIN = 5.0
"""A method is better (worse) than CQL if its mean paired Δ of the mean score is ≥ MARGIN
(≤ −MARGIN) and Δ has that sign on every seed (studies/cql_hopper's rule)."""
ASOR_BASE = {
    "preset": "paper",
    "lambda_": 0.1,
    "rho_value": 0.5,
    "rho_count": 0.5,
    "proxy": "rnd",
    "reward_form": "log",
}
"""The offline tuned examples' ASOR block (λ 0.1: SRPO's fixed value)."""


def cql_config(seed: int, asor: dict[str, Any] | None, args: argparse.Namespace) -> Any:
    """CQL as in tuned_examples/offline/cql-hopper.yaml (batch and sampled actions from the
    flags), on `args.quality` of every dynamics."""
    from ray.rllib.algorithms.cql import CQLConfig

    import rllib_asor
    from rllib_asor.algorithms.cql.offline import offline_input
    from rllib_asor.algorithms.sac.fast import fast_off_policy

    config = (
        CQLConfig()
        .environment(env_config={"dynamics": "original"})
        .env_runners(num_env_runners=0)
        .learners(num_learners=0)
        .training(
            train_batch_size_per_learner=args.batch,
            num_actions=args.num_actions,
            lr=None,
            actor_lr=1e-4,
            critic_lr=3e-4,
            alpha_lr=1e-4,
            bc_iters=args.bc_iters,
            min_q_weight=5.0,
            gamma=0.99,
            tau=0.005,
        )
        .evaluation(evaluation_interval=None)
        .debugging(seed=seed, log_level="ERROR")
    )
    offline_input(
        config, args.data, quality=args.quality, dataset_num_iters_per_learner=args.iter_updates
    )
    config = fast_off_policy(config)  # the concat-MLP critics, for every method
    if asor is not None:
        config = rllib_asor.with_asor(config, **({"seed": seed} | asor))
    return config


def run_one(method: str, seed: int, asor: dict[str, Any] | None, args: argparse.Namespace) -> dict:
    from rllib_asor.data.scoring import evaluate

    algo = cql_config(seed, asor, args).build_algo()
    t0, result = time.time(), {}
    try:
        for i in range(args.iters):
            result = algo.train()
            if (i + 1) % 5 == 0:
                print(f"  {method} seed={seed} iter {i + 1} t={time.time() - t0:.0f}s", flush=True)
        wall = time.time() - t0
        ev = evaluate(algo, args.data, episodes=args.eval_episodes, seed=1000 + seed)
    finally:
        algo.stop()
    return {
        "method": method,
        "asor": asor,
        "seed": seed,
        "quality": args.quality,
        "updates": args.iters * args.iter_updates,
        "batch": args.batch,
        "num_actions": args.num_actions,
        "wall_s": wall,
        "eval": ev,
        "asor_last": {k: float(v) for k, v in result.get("asor", {}).items() if np.isscalar(v)},
    }


def summarize(out: Path) -> str:
    """Markdown table: normalised score per dynamics and their mean (mean ± std over seeds)."""
    runs = read_runs(out / "runs")
    dyns = [d for d in (runs[0]["eval"] if runs else {}) if d != "mean"]
    lines = [
        "| quality | method | seeds | updates | "
        + " | ".join(f"{d} score" for d in dyns)
        + " | mean score | mean return | wall s / run |",
        "|---|---|---|---|" + "---|" * len(dyns) + "---|---|---|",
    ]
    table: dict[str, Any] = {}
    keys = sorted({(r["quality"], r["method"]) for r in runs}, key=lambda k: (k[0], _order(k[1])))
    for quality, method in keys:
        rs = [r for r in runs if r["quality"] == quality and r["method"] == method]

        per = {d: [r["eval"][d]["normalized_score"] for r in rs] for d in dyns}
        means = [r["eval"]["mean"]["normalized_score"] for r in rs]
        returns = [r["eval"]["mean"]["return_mean"] for r in rs]
        table[f"{quality}/{method}"] = {
            "seeds": [r["seed"] for r in rs],
            "scores": per,
            "mean_score": means,
            "mean_return": returns,
        }
        lines.append(
            f"| {quality} | {method} | {len(rs)} | {rs[0]['updates']} | "
            + " | ".join(mean_std(per[d]) for d in dyns)
            + f" | {mean_std(means)} | {mean_std(returns)} | {np.mean([r['wall_s'] for r in rs]):.0f} |"
        )
    for quality, method in keys:
        base = {r["seed"]: r for r in runs if r["quality"] == quality and r["method"] == "cql"}
        mine = {r["seed"]: r for r in runs if r["quality"] == quality and r["method"] == method}
        seeds = sorted(set(base) & set(mine))
        if method == "cql" or not seeds:
            continue
        deltas = [_score(mine[s]) - _score(base[s]) for s in seeds]
        per = ", ".join(f"seed {s}: {d:+.1f}" for s, d in zip(seeds, deltas, strict=True))
        verdict = paired_verdict(deltas)
        table[f"{quality}/{method}"]["minus_cql"] = {
            "seeds": seeds,
            "deltas": deltas,
            "verdict": verdict,
        }
        lines.append(f"\n{quality}: {method} − cql (mean score, paired by seed): mean "
                     f"{np.mean(deltas):+.1f} ({per}): {verdict}.")  # fmt: skip
    md = "\n".join(lines) + "\n"
    (out / "table.md").write_text(md)
    (out / "summary.json").write_text(json.dumps(table, indent=1))
    return md


def _score(run: dict[str, Any]) -> float:
    return float(run["eval"]["mean"]["normalized_score"])


def paired_verdict(deltas: list[float]) -> str:
    """The rule's verdict on a method − CQL, paired by seed."""
    return {1: "better", -1: "worse", 0: "no clear difference at this budget"}[
        sign_rule(deltas, MARGIN)
    ]


def _order(method: str) -> int:
    return {"cql": 0, "srpo": 1, "asor": 2}.get(method, 3)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--data", default="data/offline/hopper", help="task dir of `offline collect`")
    p.add_argument("--quality", default="medium", help="random, medium, expert, medium-replay")
    p.add_argument("--methods", nargs="+", default=list(DEFAULT_METHODS))
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--first-seed", type=int, default=0)
    p.add_argument("--iters", type=int, default=20, help="training iterations per run")
    p.add_argument("--iter-updates", type=int, default=100, help="gradient updates per iteration")
    p.add_argument("--bc-iters", type=int, default=20, help="CQL's behaviour-cloning updates")
    p.add_argument("--batch", type=int, default=256, help="train batch (transitions)")
    p.add_argument(
        "--num-actions",
        type=int,
        default=10,
        help="actions CQL samples per state for its conservative term (RLlib default 10; "
        "each costs a twin-critic pass over the batch: the update's main cost on a CPU)",
    )
    p.add_argument("--eval-episodes", type=int, default=3, help="episodes per dynamics")
    p.add_argument("--out", default="studies/out/offline_cql")
    p.add_argument("--summarize-only", action="store_true")
    args = p.parse_args(argv)
    out = Path(args.out)
    if not args.summarize_only:
        import ray

        import rllib_asor.envs  # noqa: F401

        args.data = str(Path(args.data).resolve())  # Ray Data reads it from its own workers
        # Ray Data runs OfflinePreLearner in 2 one-CPU actors next to its read task: with 2
        # logical CPUs the pipeline waits forever for a third (measured: 3/2 CPU requested).
        start_local_ray(4)
        (out / "runs").mkdir(parents=True, exist_ok=True)
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            for text in args.methods:
                name, asor = parse_method(text, plain="cql", base=ASOR_BASE)
                run_if_missing(
                    run_file(out / "runs", f"{args.quality}-{name}-{seed}"),
                    f"{args.quality} {name} seed {seed}",
                    lambda: run_one(name, seed, asor, args),  # noqa: B023 (called at once)
                )
        ray.shutdown()
    print(summarize(out))


if __name__ == "__main__":
    main()
