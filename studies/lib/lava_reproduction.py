"""Lava world: PPO vs PPO+SRPO vs PPO+ASOR (the paper's Appendix figure), ≥ 5 seeds each.

Every run trains for the same number of env steps, then its greedy policy is evaluated on
each bottom-lava row (the paper's Fig. (b)); the training-return curve is recorded too. For
one ASOR run the RND pseudo-count over the grid is drawn as a heatmap (Fig. (c)).

    python -m studies.lib.lava_reproduction --seeds 5 --steps 100000 --out studies/out/lava

Methods are named on the command line as `name:key=value,...` over AsorConfig fields
(`ppo` = no ASOR), so the λ/ρ/form study uses the same script:

    python -m studies.lib.lava_reproduction --methods ppo asor:lambda_=0.003,reward_form=centered

`asor:` (or `asor`) alone means the AsorConfig defaults. `--layout E` trains and evaluates on
layout E (start (0,3)); keep each layout in its own `--out` (the run files are named
`<method>-<seed>.json.gz`, and the summary skips runs of another layout). Every run records
`escaped_trap`: its greedy policy reaches the goal on the trap row (`TRAP_ROW`, row 2).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from rllib_asor.report.stats import bootstrap_ci
from studies.lib.common import (
    round_floats,
    run_method_seed_grid,
    runs_made_otherwise,
    start_local_ray,
)
from studies.lib.run_files import read_run, run_file, run_paths, write_run

DEFAULT_METHODS = (
    "ppo",
    "srpo:preset=paper,mode=srpo",
    "asor-paper:preset=paper,mode=asor",
    "asor:mode=asor",
)
"""PPO, the published SRPO and ASOR (`preset=paper`), and ASOR's robust default."""
TRAP_ROW = 2
"""The hardest lava row: the shortest route for rows 3-5 crosses its cells (PPO's known trap)."""


def parse_method(text: str) -> tuple[str, dict[str, Any] | None]:
    """`name[:k=v,...]` → (name, asor settings or None for plain PPO)."""
    name, _, rest = text.partition(":")
    if name == "ppo" and not rest:
        return name, None
    settings: dict[str, Any] = {}
    for item in filter(None, rest.split(",")):
        key, _, value = item.partition("=")
        settings[key] = _parse_value(value)
    return name, settings


def _parse_value(value: str) -> Any:
    try:
        return json.loads(value)
    except json.JSONDecodeError:
        return value


def ppo_config(seed: int, asor: dict[str, Any] | None, args: argparse.Namespace) -> Any:
    """The shared PPO config (identical for every method), plus ASOR when given."""
    from ray.rllib.algorithms.ppo import PPOConfig

    import rllib_asor

    config = (
        PPOConfig()
        .environment(
            "rllib_asor/LavaWorld-v0",
            env_config={"obs_mode": "onehot", "layout": getattr(args, "layout", "B")},
        )
        .env_runners(num_env_runners=0, num_envs_per_env_runner=8)
        .training(
            lr=args.lr,
            gamma=0.99,
            lambda_=0.95,
            entropy_coeff=args.entropy,
            train_batch_size=2000,
            minibatch_size=256,
            num_epochs=6,
        )
        .rl_module(model_config={"fcnet_hiddens": [64, 64]})
        .debugging(seed=seed)
    )
    if asor is not None:
        config = rllib_asor.with_asor(config, **({"seed": seed} | asor))
    return config


def greedy_returns(module: Any, episodes: int = 3, layout: str = "B") -> dict[int, float]:
    """Mean return of the greedy policy on each lava row (deterministic env → few episodes)."""
    from rllib_asor.envs.lava import LAVA_ROWS, LavaWorldEnv
    from rllib_asor.evaluation.rollout import module_actor, rollout, to_int

    out = {}
    for row in LAVA_ROWS:
        env = LavaWorldEnv(lava_row=row, layout=layout)
        rewards: list[float] = []  # every step's, summed in order over the episodes
        rollout(
            module_actor(module), env, episodes, action_fn=to_int,
            watch=lambda ep, a, r, info, rewards=rewards: rewards.append(r),
        )  # fmt: skip
        out[row] = sum(rewards) / episodes
    return out


def pseudo_counts(learner: Any) -> dict[int, list[list[float]]]:
    """RND count proxy −‖f̂ − f‖² per cell (NaN on lava) for every lava row."""
    import torch

    from rllib_asor.asor.proxy import ProxyInputs
    from rllib_asor.envs.lava import GRID_SIZE, LAVA_ROWS, LavaWorldEnv, observation_at

    proxy = learner.module["asor_disc.default_policy"].unwrapped().trainer
    grids = {}
    for row in LAVA_ROWS:
        grid = np.full((GRID_SIZE, GRID_SIZE), np.nan)
        cells = LavaWorldEnv.cells(lava_row=row)
        obs = torch.as_tensor(np.stack([observation_at(r, c, row) for r, c in cells]))
        counts = proxy.proxy.count(ProxyInputs(obs.float())).numpy()
        for (r, c), v in zip(cells, counts, strict=True):
            grid[r, c] = v
        grids[row] = grid.tolist()
    return grids


def run_one(config: dict[str, Any]) -> dict[str, Any]:
    """Tune function trainable: train one (method, seed) to the budget, then evaluate."""
    spec = config["spec"]
    import torch
    from ray import tune

    import rllib_asor.envs  # noqa: F401

    torch.set_num_threads(1)
    args = argparse.Namespace(**spec["args"])
    algo = ppo_config(spec["seed"], spec["asor"], args).build_algo()
    curve = []
    steps, t0 = 0, time.time()
    while steps < args.steps:
        result = algo.train()
        steps = result["num_env_steps_sampled_lifetime"]
        ret = result["env_runners"].get("episode_return_mean", float("nan"))
        asor = result.get("asor", {})
        curve.append([steps, ret])
        tune.report(
            {
                "steps": steps,
                "episode_return_mean": ret,
                **{f"asor_{k}": v for k, v in asor.items()},
            }
        )
    layout = getattr(args, "layout", "B")
    rows = greedy_returns(algo.get_module(), layout=layout)
    final = {
        "method": spec["method"],
        "seed": spec["seed"],
        "layout": layout,
        "steps": steps,
        "wall_s": time.time() - t0,
        "greedy_return_per_row": rows,
        "greedy_return_mean": float(np.mean(list(rows.values()))),
        "escaped_trap": bool(rows[TRAP_ROW] > 0),
        "train_return_last": float(np.nanmean([c[1] for c in curve[-3:]])),
        "curve": round_floats(curve),
        "asor_last": {k: float(v) for k, v in result.get("asor", {}).items()},
    }
    if (
        spec["asor"] is not None
        and spec["asor"].get("mode", "asor") in ("asor", "count")
        and spec["seed"] == 0
    ):
        final["pseudo_counts"] = pseudo_counts(algo.learner_group._learner)
    write_run(run_file(Path(spec["out"]) / "runs", f"{spec['method']}-{spec['seed']}"), final)
    algo.stop()
    tune.report({"steps": steps, "greedy_return_mean": final["greedy_return_mean"], "done": True})
    return final


def escaped_trap(run: dict[str, Any]) -> bool:
    """The run's `escaped_trap` (derived from its row-2 greedy return for older run files)."""
    if "escaped_trap" in run:
        return bool(run["escaped_trap"])
    return run["greedy_return_per_row"][str(TRAP_ROW)] > 0


def load_runs(out: Path, layout: str = "B") -> list[dict[str, Any]]:
    """The run files under `out/runs` of `layout` (files without a layout are B); the others
    are skipped with a warning."""
    runs, other = [], []
    for p in run_paths(out / "runs"):
        run = read_run(p)
        if run.get("layout", "B") == layout:
            runs.append(run)
        else:
            other.append(p.name)
    if other:
        print(f"warning: skipped {len(other)} runs not of layout {layout}: {', '.join(other)}")
    return runs


def summarize(out: Path, methods: list[str], layout: str = "B", plots: bool = True) -> str:
    """Markdown table (+ curves.png and pseudo_count.png if `plots`) from the per-run JSON files
    of `layout`."""
    from rllib_asor.envs.lava import LAVA_ROWS, optimal_return

    runs = load_runs(out, layout)
    lines = [
        "| method | n | greedy return, mean ± std | 95% bootstrap CI | "
        + " | ".join(f"row {r}" for r in LAVA_ROWS)
        + " | escaped | train return (last) | env steps |",
        "|---|---|---|---|" + "---|" * len(LAVA_ROWS) + "---|---|---|",
    ]
    table = {}
    for name in methods:
        rs = [r for r in runs if r["method"] == name]
        if not rs:
            continue
        g = np.array([r["greedy_return_mean"] for r in rs])
        lo, hi = bootstrap_ci(g)
        per_row = [np.mean([r["greedy_return_per_row"][str(k)] for r in rs]) for k in LAVA_ROWS]
        train = np.mean([r["train_return_last"] for r in rs])
        escaped = sum(escaped_trap(r) for r in rs)
        table[name] = {
            "n": len(rs),
            "mean": float(g.mean()),
            "std": float(g.std(ddof=1)) if len(g) > 1 else 0.0,
            "ci": [lo, hi],
            "per_row": per_row,
            "escaped_trap": escaped,
        }
        lines.append(
            f"| {name} | {len(rs)} | {g.mean():.3f} ± {table[name]['std']:.3f} | "
            f"[{lo:.3f}, {hi:.3f}] | "
            + " | ".join(f"{v:.3f}" for v in per_row)
            + f" | {escaped} / {len(rs)} | {train:.3f} | "
            + f"{int(np.mean([r['steps'] for r in rs]))} |"
        )
    optimum = [optimal_return(k, layout) for k in LAVA_ROWS]
    lines.append(
        f"| optimum (row known) | – | {np.mean(optimum):.3f} | – | "
        + " | ".join(f"{v:.3f}" for v in optimum)
        + " | – | – | – |"
    )
    if plots:
        _plots(out, runs, methods)
    (out / "summary.json").write_text(json.dumps(table, indent=1))
    md = "\n".join(lines) + "\n"
    (out / "table.md").write_text(md)
    return md


def _plots(out: Path, runs: list[dict], methods: list[str]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for name in methods:
        rs = [r for r in runs if r["method"] == name]
        if not rs:
            continue
        n = min(len(r["curve"]) for r in rs)
        x = np.array([c[0] for c in rs[0]["curve"][:n]])
        y = np.array([[c[1] for c in r["curve"][:n]] for r in rs])
        m, s = np.nanmean(y, 0), np.nanstd(y, 0)
        ax.plot(x, m, label=name)
        ax.fill_between(x, m - s, m + s, alpha=0.2)
    ax.set_xlabel("env steps")
    ax.set_ylabel("training episode return (mean ± std over seeds)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "curves.png", dpi=100)
    plt.close(fig)
    with_counts = [r for r in runs if "pseudo_counts" in r]
    if with_counts:
        counts = with_counts[0]["pseudo_counts"]
        fig, axes = plt.subplots(1, len(counts), figsize=(3.2 * len(counts), 3.2))
        for ax, (row, grid) in zip(np.atleast_1d(axes), sorted(counts.items()), strict=True):
            im = ax.imshow(np.array(grid, dtype=float), cmap="viridis")
            ax.set_title(f"lava row {row}")
            ax.set_xticks(range(7))
            ax.set_yticks(range(7))
            fig.colorbar(im, ax=ax, fraction=0.046)
        fig.suptitle(
            f"RND pseudo-count −‖f̂−f‖² ({with_counts[0]['method']}, seed 0; higher = more visited)"
        )
        fig.tight_layout()
        fig.savefig(out / "pseudo_count.png", dpi=100)
        plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--methods", nargs="+", default=list(DEFAULT_METHODS))
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--lr", type=float, default=5e-4)
    parser.add_argument("--entropy", type=float, default=0.01)
    parser.add_argument("--parallel", type=int, default=2, help="trials at once (1 CPU each)")
    parser.add_argument("--layout", choices=("B", "E"), default="B", help="lava world layout")
    parser.add_argument("--out", default="studies/out/lava")
    parser.add_argument("--summarize-only", action="store_true")
    args = parser.parse_args(argv)
    out = Path(args.out).resolve()
    methods = [parse_method(m) for m in args.methods]
    names = [n for n, _ in methods]
    if not args.summarize_only:
        seeds = range(args.first_seed, args.first_seed + args.seeds)
        if clash := runs_made_otherwise(
            out, names, seeds, {"layout": args.layout}, defaults={"layout": "B"}
        ):
            parser.error(
                f"{out}/runs holds runs of another layout ({', '.join(clash)}): use another --out"
            )
        start_local_ray(args.parallel)
        keys = ("steps", "lr", "entropy", "layout")
        shared = {k: v for k, v in vars(args).items() if k in keys}
        run_method_seed_grid(run_one, methods, seeds, shared, out)
    md = summarize(out, names, args.layout)
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
