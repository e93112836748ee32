"""Race PPO(+ASOR) end to end, side by side across source trees.

One measurement = one fresh process that builds `studies.lib.race_learning.race_config` (the race
network, a map drawn per episode, 1000-step episodes, train batch 1024, minibatch 256, 4 epochs,
ASOR's default of that tree with `obs_keys=[agent, destination]`), runs `--warmup` iterations,
then times `--iters` calls of `algo.train()` by the wall clock: env steps/s end to end
(sampling, connectors, forward passes, the learner update, ASOR's piece, metrics). The default
warm-up (24 iterations) measures ASOR's steady state: the first race episodes end after ~16
iterations (1000 steps per env), and from then on the archive's states join the
discriminator's batch (older measurements used 2, the archive-empty start).

`--trees A B ...` measures each source tree (a checkout, e.g. `git worktree add /tmp/old <commit>`)
in turn, `--rounds` times, interleaved (A, B, A, B, ...), so load drifts hit every tree alike;
each process imports `studies` and `rllib_asor` from its tree (PYTHONPATH), this file is the
only code they share. Layouts (`--layouts`, `LAYOUTS`): `local` (race_learning's: sampling in
the driver, 16 envs, one core), `runners2` (the race YAMLs': 2 env runners × 8 envs at 0.5 CPU
each), `overlap1` / `overlap2` (1 × 16 or 2 × 8 with `OverlappedPPO`; skipped for trees
without it), `overlap1drop` (`overlap1` with `drop_bootstrap_rows`: the fast example's
layout; skipped likewise). Networks (`--nets`, `NETS`): `default` (the tuned examples') and
`small`.

    git worktree add /tmp/race-old fb9d406
    python benchmarks/race_speed.py --trees /tmp/race-old . --rounds 3 --out benchmarks/out/race_speed
    python benchmarks/race_speed.py --trees /tmp/race-old . --layouts runners2 overlap1 --nets default small
    python benchmarks/race_speed.py --trees . --profile --layouts local   # cProfile, one process

Writes OUT/race_speed.json (every measurement) and prints a markdown table (median env steps/s
per tree, layout and network, and its ratio to the first tree's fastest).
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

LAYOUTS = {
    "local": (0, 16, False, False),
    "runners2": (2, 8, False, False),
    "overlap1": (1, 16, True, False),
    "overlap2": (2, 8, True, False),
    "overlap1drop": (1, 16, True, True),
}
"""Layout → (env runners, envs per runner, overlapped sampling: rllib_asor/algorithms/ppo/overlap.py,
PPO without its masked bootstrap rows: rllib_asor/algorithms/ppo/lean.py)."""

NETS: dict[str, dict[str, Any]] = {
    "default": {},
    "small": {"cnn_channels": [8, 16], "attn_token_size": 8},
}
"""Race network → `model_config` over `RaceNetModule`'s defaults. `small`: half the CNN channels
and half as many attention tokens (its success rate: docs/results.md, the race speed row)."""


def measure_here(args: argparse.Namespace) -> dict[str, Any]:
    """Build the race PPO(+ASOR) config of the tree on sys.path and time `--iters` iterations."""
    import ray
    import torch
    from ray.rllib.core import DEFAULT_MODULE_ID

    try:  # the study runner's home; older trees kept it under benchmarks/
        from studies.lib.race_learning import race_config
    except ImportError:
        from benchmarks.race_learning import race_config

    torch.set_num_threads(args.learner_threads)
    runners, envs, overlap, drop = LAYOUTS[args.layout]
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    ns = argparse.Namespace(
        steps=10**7, batch=1024, epochs=4, envs=envs, max_episode_steps=1000, train_map=None
    )
    asor = None if args.no_asor else {"mode": "asor"}
    if net := NETS[args.net]:  # through race_ppo_config, which every tree's race_config calls
        import rllib_asor.race.config as race

        base_config = race.race_ppo_config

        def race_ppo_config(*a: Any, **kw: Any) -> Any:
            return base_config(*a, **kw | {"model_config": (kw.get("model_config") or {}) | net})

        race.race_ppo_config = race_ppo_config
    config = race_config(0, asor, ns)
    if runners:
        config = config.env_runners(
            num_env_runners=runners,
            num_envs_per_env_runner=envs,
            num_cpus_per_env_runner=1 / runners,
        )
    switches = [(("algorithms.ppo.overlap", "rllib.overlap"), "overlap_sampling")] if overlap else []
    switches += [(("algorithms.ppo.lean", "rllib.lean_ppo"), "drop_bootstrap_rows")] if drop else []
    for modules, name in switches:
        switch = None
        for module in modules:  # this tree's path, then the package's earlier one
            try:
                switch = getattr(importlib.import_module(f"rllib_asor.{module}"), name)
                break
            except (ImportError, AttributeError):
                continue
        if switch is None:  # a tree from before it existed
            ray.shutdown()
            return {"unsupported": True}
        config = switch(config)
    algo = config.build_algo()
    learner_net = algo.learner_group._learner.module[DEFAULT_MODULE_ID].settings
    assert all(learner_net[k] == v for k, v in NETS[args.net].items()), learner_net
    for _ in range(args.warmup):
        algo.train()
    steps0 = algo.train()["num_env_steps_sampled_lifetime"]
    prof = None
    if args.profile:
        import cProfile

        prof = cProfile.Profile()
        prof.enable()
    t0 = time.perf_counter()
    for _ in range(args.iters):
        result = algo.train()
    wall = time.perf_counter() - t0
    if prof is not None:
        import pstats

        prof.disable()
        stats = pstats.Stats(prof)
        stats.sort_stats("cumulative").print_stats(45)
        stats.sort_stats("tottime").print_stats(30)
    steps = result["num_env_steps_sampled_lifetime"] - steps0
    policy = result.get("learners", {}).get(DEFAULT_MODULE_ID, {})
    algo.stop()
    ray.shutdown()
    return {
        "env_steps": steps,
        "wall_s": wall,
        "env_steps_per_s": steps / wall,
        # Rows the policy trained on in the last iteration (PPO: minibatches × 256) and the
        # archive's size: ASOR's steady state has archive states in the discriminator's batch.
        "policy_rows_trained": float(policy.get("num_module_steps_trained", "nan")),
        "archive_states": float(result.get("asor", {}).get("archive_states", "nan")),
    }


def run_tree(tree: Path, layout: str, net: str, args: argparse.Namespace) -> dict[str, Any]:
    """One measurement in a fresh process that imports from `tree`."""
    env = {**os.environ, "PYTHONPATH": str(tree), "OMP_NUM_THREADS": "1", "PYTHONHASHSEED": "0"}
    cmd = [
        sys.executable, __file__, "--single", "--layout", layout, "--net", net,
        "--iters", str(args.iters), "--warmup", str(args.warmup),
        "--learner-threads", str(args.learner_threads),
    ] + (["--no-asor"] if args.no_asor else []) + (["--profile"] if args.profile else [])  # fmt: skip
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"{tree} ({layout}) failed:\n{proc.stderr[-3000:]}")
    if args.profile:
        print(proc.stdout)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--trees", nargs="+", default=["."], help="source trees to compare")
    parser.add_argument("--layouts", nargs="+", choices=list(LAYOUTS), default=list(LAYOUTS))
    parser.add_argument("--nets", nargs="+", choices=list(NETS), default=["default"])
    parser.add_argument(
        "--combos",
        nargs="+",
        default=None,
        help="explicit LAYOUT:NET pairs (e.g. runners2:default overlap1drop:small) instead of "
        "every layout with every net",
    )
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--iters", type=int, default=8, help="timed iterations (1024 steps each)")
    parser.add_argument(
        "--warmup",
        type=int,
        default=24,
        help="untimed iterations; ≥ 17 reaches ASOR's steady state (archive states in its batch)",
    )
    parser.add_argument("--no-asor", action="store_true", help="plain PPO")
    parser.add_argument(
        "--learner-threads", type=int, default=1, help="torch threads of the driver (Learner)"
    )
    parser.add_argument("--profile", action="store_true", help="print a cProfile of the timing")
    parser.add_argument("--out", default="benchmarks/out/race_speed")
    parser.add_argument("--single", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--layout", default="local", help=argparse.SUPPRESS)
    parser.add_argument("--net", default="default", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.single:
        print(json.dumps(measure_here(args)))
        return 0
    trees = [Path(t).resolve() for t in args.trees]
    rows: list[dict[str, Any]] = []
    combos = [(lay, net) for lay in args.layouts for net in args.nets]
    if args.combos:
        combos = [tuple(c.split(":", 1)) for c in args.combos]
        if bad := [c for c in combos if len(c) != 2 or c[0] not in LAYOUTS or c[1] not in NETS]:
            parser.error(
                f"--combos {bad}: allowed LAYOUT:NET with LAYOUT in {', '.join(LAYOUTS)} "
                f"and NET in {', '.join(NETS)}"
            )
    for r in range(args.rounds):
        for layout, net in combos:
            for tree in trees:
                res = run_tree(tree, layout, net, args)
                if res.get("unsupported"):
                    continue
                rows.append(res | {"tree": str(tree), "layout": layout, "net": net, "round": r})
                rate = res["env_steps_per_s"]
                print(f"round {r} {layout} {net} {tree}: {rate:.0f} env steps/s", flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    def rates(tree: Path, layout: str, net: str) -> list[float]:
        return [
            x["env_steps_per_s"]
            for x in rows
            if (x["tree"], x["layout"], x["net"]) == (str(tree), layout, net)
        ]

    # Every row against the first tree's best layout (its fastest median) of the same run.
    base = max(statistics.median(v) for lay, net in combos if (v := rates(trees[0], lay, net)))
    lines = [
        "| tree | layout | net | env steps/s (median) | per round | ÷ first tree's best |",
        "|---|---|---|---|---|---|",
    ]
    for layout, net in combos:
        for tree in trees:
            if not (v := rates(tree, layout, net)):
                continue
            med = statistics.median(v)
            per = ", ".join(f"{x:.0f}" for x in v)
            lines.append(
                f"| {tree.name} | {layout} | {net} | {med:.0f} | {per} | {med / base:.2f} |"
            )
    md = "\n".join(lines) + "\n"
    meta = {"load_avg_after": os.getloadavg(), "args": vars(args), "rows": rows}
    (out / "race_speed.json").write_text(json.dumps(meta, indent=1))
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
