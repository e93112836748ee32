"""ESCP speed side by side: ESCP and ESCP+ASOR vs the project's fast SAC
(and Stable-Baselines3 SAC when installed), env steps/s while learning, in one process.

All runners train on `rllib_asor/Walker2dShift-v0` with 40 gravity tasks (ESCP needs
`info["dynamics_id"]`; the SAC runners get the same env), one local env, batch 256,
γ 0.99, τ 0.005, and **one gradient step per env step** after `--warmup` steps (the same
update-to-data ratio for all). Networks: SAC 256x256 ReLU (the project's SAC tuned examples);
ESCP its own π/Q 128-64 LeakyReLU plus the encoder (fc128-GRU64 over 16 steps), as ESCP runs;
`escp_256` gives ESCP SAC's 256x256 networks. RMDM is switched on from the first update
(`rmdm_min_replay = warmup`, `rmdm_min_task_fraction = 0`), so the encoder's backward pass is
timed (ESCP's steady state). One torch thread; runners are timed in interleaved rounds after
their warm-up (`benchmarks/sac_speed.py`'s method), so load drift hits all alike; the median
over rounds of each runner's rate ÷ fast SAC's rate in the same round is the headline ratio.

    nice -n 5 .venv/bin/python -m benchmarks.escp_speed --rounds 6 --block 256 \
        --out benchmarks/out/escp_speed

Writes OUT/escp_speed.json and prints a markdown table.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path
from typing import Any

from benchmarks.common import (
    median_paired_ratios,
    start_local_ray,
    time_interleaved,
    write_json,
)
from benchmarks.sac_speed import Sb3Runner, sac_config

ENV_ID = "rllib_asor/Walker2dShift-v0"
ENV_CONFIG = {"params": ["gravity"], "num_tasks": 40, "task_seed": 0}
RUNNERS = ("sb3", "sac", "escp", "escp_asor", "escp_256")
LABELS = {
    "sb3": "Stable-Baselines3 `SAC` (256x256)",
    "sac": "RLlib SAC, rllib_asor fast path (256x256)",
    "escp": "ESCP, `EscpConfig()` (its 128-64 nets + encoder)",
    "escp_asor": "ESCP + ASOR, `with_asor(EscpConfig())`",
    "escp_256": "ESCP with SAC's 256x256 nets",
}


def escp_config(args: argparse.Namespace, hiddens: list[int] | None = None) -> Any:
    from rllib_asor.algorithms.escp.config import EscpConfig

    cfg = (
        EscpConfig()
        .environment(ENV_ID, env_config=ENV_CONFIG)
        .env_runners(num_env_runners=0, num_envs_per_env_runner=1)
        .learners(num_learners=0)
        .training(
            num_steps_sampled_before_learning_starts=args.warmup,
            replay_buffer_config={"type": "EpisodeReplayBuffer", "capacity": 100_000},
            training_intensity=256,
        )
        .escp(rmdm_min_replay=args.warmup, rmdm_min_task_fraction=0.0)
        .reporting(min_sample_timesteps_per_iteration=1)
        .debugging(seed=args.seed)
    )
    if hiddens:
        cfg.rl_module(model_config={"fcnet_hiddens": hiddens, "fcnet_activation": "relu"})
    return cfg


class RllibRunner:
    """An RLlib algorithm stepped with `algo.train()` until a step target."""

    def __init__(self, name: str, args: argparse.Namespace) -> None:
        import rllib_asor

        if name == "sac":
            from rllib_asor.algorithms.sac.fast import fast_off_policy

            config = fast_off_policy(sac_config(args, ENV_ID, ENV_CONFIG))
        elif name == "escp_asor":
            config = rllib_asor.with_asor(escp_config(args), seed=args.seed)
        else:
            config = escp_config(args, [256, 256] if name == "escp_256" else None)
        self.algo = config.build_algo()
        self.steps = 0

    def run(self, steps: int) -> int:
        target = self.steps + steps
        while self.steps < target:
            self.steps = int(self.algo.train()["num_env_steps_sampled_lifetime"])
        return self.steps

    def stop(self) -> None:
        self.algo.stop()


def measure(args: argparse.Namespace) -> dict[str, Any]:
    names = list(args.runners)
    if "sb3" in names:
        try:
            import stable_baselines3  # noqa: F401
        except ImportError:
            print("sb3: stable_baselines3 is not installed; skipped")
            names.remove("sb3")
    runners: dict[str, Any] = {}
    for name in names:
        t0 = time.perf_counter()
        runners[name] = (
            Sb3Runner(args, ENV_ID, ENV_CONFIG) if name == "sb3" else RllibRunner(name, args)
        )
        runners[name].run(args.warmup + args.block)  # warm-up, then a first learning block
        print(f"{name}: built + warm-up in {time.perf_counter() - t0:.1f}s", flush=True)
    rounds = time_interleaved(runners, args.rounds, lambda _: args.block)
    for runner in runners.values():
        runner.stop()
    rates = {
        n: sum(x["steps"] for x in rs) / sum(x["wall_s"] for x in rs) for n, rs in rounds.items()
    }
    paired = {f"vs_{b}": median_paired_ratios(rounds, b) for b in ("sac", "sb3") if b in rounds}
    return {
        "env": ENV_ID,
        "env_config": ENV_CONFIG,
        "settings": vars(args),
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version()},
        "env_steps_per_s": rates,
        "per_round": rounds,
        "median_paired_ratios": paired,
        "load_avg_after": os.getloadavg(),
    }


def table(res: dict[str, Any]) -> str:
    rates = res["env_steps_per_s"]
    vs_sac = res["median_paired_ratios"].get("vs_sac", {})
    vs_sb3 = res["median_paired_ratios"].get("vs_sb3", {})
    lines = [
        "| runner | env steps/s while learning | ÷ fast SAC (median of rounds) | ÷ SB3 |",
        "|---|---|---|---|",
    ]
    for name, rate in rates.items():
        a = f"{vs_sac[name]:.2f}" if name in vs_sac else "–"
        b = f"{vs_sb3[name]:.2f}" if name in vs_sb3 else "–"
        lines.append(f"| {LABELS[name]} | {rate:.1f} | {a} | {b} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--runners", nargs="+", choices=RUNNERS, default=list(RUNNERS))
    p.add_argument("--warmup", type=int, default=1000, help="env steps before learning")
    p.add_argument("--block", type=int, default=256, help="env steps per runner and round")
    p.add_argument("--rounds", type=int, default=6)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="benchmarks/out/escp_speed")
    args = p.parse_args(argv)
    start_local_ray()
    res = measure(args)
    write_json(Path(args.out) / "escp_speed.json", res)
    print(table(res))


if __name__ == "__main__":
    main()
