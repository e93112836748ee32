"""SAC speed side by side: Stable-Baselines3 SAC vs our RLlib SAC vs SAC+ASOR.

Every runner trains on `rllib_asor/HopperShift-v0` (body mass, dof damping and wind drawn per
episode) with the same settings: one local env, 256x256 ReLU MLPs for actor and twin critics,
batch 256, lr 3e-4, γ 0.99, τ 0.005, automatic entropy (initial α 1), a uniform replay buffer of
100k transitions, 1,000 warm-up steps before learning and then **one gradient step per env step**
(the same update-to-data ratio for all). All runners live in this one process with one torch
thread; after every runner's warm-up they are timed in interleaved rounds (runner A block,
runner B block, ..., next round), so a change in machine load hits them all alike.

Runners (`--runners`):

- `sb3`: `stable_baselines3.SAC("MlpPolicy", ...)`, train_freq 1, gradient_steps 1.
- `rllib_stock`: RLlib 2.60 `SACConfig` as a user writes it today (EpisodeReplayBuffer, RLlib's
  own training step: one Learner call per gradient step, episodes through the learner connector).
- `rllib`: the same config through `rllib_asor.fast_off_policy(config)` (the fast path the SAC
  tuned examples and `with_asor` use; rllib_asor/algorithms/sac/fast.py).
- `asor_stock`: ASOR on RLlib's stock path (`learner_config_dict["fast_off_policy"] = False`).
- `asor`: `rllib_asor.with_asor(fast_off_policy(config))` (the robust default on the fast path:
  the discriminator and RND take one minibatch per Learner call of 16 SAC steps).
- `asor_every_step`: the same with `aux_epochs=1`: discriminator and RND trained with every SAC
  gradient step (an earlier default of the fast path).

Stable-Baselines3 is a benchmark-only dependency (`pip install -e ".[bench]"`, which keeps torch
pinned; it is never needed by `make test`). Run:

    nice -n 5 .venv/bin/python -m benchmarks.sac_speed --rounds 8 --block 256 --stock-block 128 \
        --out benchmarks/out/sac_speed

`--cql-updates N --runners none` times CQL Learner steps instead (stock vs fast critics, with
and without ASOR; random Hopper-shaped batches, no dataset needed):

    nice -n 5 .venv/bin/python -m benchmarks.sac_speed --cql-updates 100 --runners none

Rates are steps/s summed over rounds; on a shared machine the load drifts between rounds, so
the JSON and table also give, per runner, the median over rounds of its rate ÷ SB3's rate in the
same round. The slow `*_stock` runners take `--stock-block` steps per round (fewer, so that
the rounds stay short). It writes OUT/sac_speed.json (env steps/s per runner and round, ratios
to SB3 and to RLlib stock) and prints a markdown table. `--profile RUNNER` instead trains RUNNER alone for
`--block` steps after its warm-up under cProfile and prints where the time went.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import median_paired_ratios, time_interleaved
from rllib_asor.data.collect import MUJOCO_SAC_MODEL, MUJOCO_SAC_TRAINING

ENV_ID = "rllib_asor/HopperShift-v0"
ENV_PARAMS = ["mass", "damping", "wind"]
RUNNERS = ("sb3", "rllib_stock", "rllib", "asor_stock", "asor", "asor_every_step")
LABELS = {
    "sb3": "Stable-Baselines3 `SAC`",
    "rllib_stock": "RLlib 2.60 `SACConfig` as a user writes it (stock path)",
    "rllib": "RLlib SAC, rllib_asor fast path (`fast_off_policy`, tuned examples)",
    "asor_stock": "SAC + ASOR on the stock path",
    "asor": "SAC + ASOR on the fast path, `with_asor(fast_off_policy(SACConfig...))`",
    "asor_every_step": "SAC + ASOR, fast path, aux nets trained every SAC step (`aux_epochs=1`)",
}


class Sb3Runner:
    """Stable-Baselines3 SAC with the shared settings (on `env_id` made with `env_config`)."""

    def __init__(
        self,
        args: argparse.Namespace,
        env_id: str = ENV_ID,
        env_config: dict[str, Any] | None = None,
    ) -> None:
        import gymnasium as gym
        from stable_baselines3 import SAC

        import rllib_asor.envs  # noqa: F401

        env = gym.make(env_id, **(env_config or {"params": ENV_PARAMS}))
        self.model = SAC(
            "MlpPolicy",
            env,
            learning_rate=3e-4,
            buffer_size=100_000,
            learning_starts=args.warmup,
            batch_size=256,
            tau=0.005,
            gamma=0.99,
            train_freq=1,
            gradient_steps=1,
            ent_coef="auto",  # initial α 1.0, as RLlib's initial_alpha
            policy_kwargs={"net_arch": [256, 256]},
            seed=args.seed,
            device="cpu",
            verbose=0,
        )
        self.steps = 0

    def run(self, steps: int) -> int:
        self.model.learn(total_timesteps=steps, reset_num_timesteps=False, progress_bar=False)
        self.steps = int(self.model.num_timesteps)
        return self.steps

    def stop(self) -> None:
        self.model.env.close()


def sac_config(
    args: argparse.Namespace,
    env_id: str = ENV_ID,
    env_config: dict[str, Any] | None = None,
    config_class: type | None = None,
) -> Any:
    """RLlib SAC with the shared settings (what a user writes for SB3-like SAC); a
    `config_class` such as `FastSACConfig` instead of `SACConfig`."""
    from ray.rllib.algorithms.sac import SACConfig

    return (
        (config_class or SACConfig)()
        .environment(env_id, env_config=env_config or {"params": ENV_PARAMS})
        .env_runners(num_env_runners=0, num_envs_per_env_runner=1)
        .learners(num_learners=0)
        .training(
            **MUJOCO_SAC_TRAINING,
            num_steps_sampled_before_learning_starts=args.warmup,
            replay_buffer_config={"type": "EpisodeReplayBuffer", "capacity": 100_000},
            # replayed rows per sampled step: 256 = one gradient step of batch 256 per env step
            training_intensity=256,
        )
        .rl_module(model_config=MUJOCO_SAC_MODEL)
        .reporting(min_sample_timesteps_per_iteration=1)
        .debugging(seed=args.seed)
    )


class RllibRunner:
    """One of our RLlib SAC variants, stepped with `algo.train()` until a step target."""

    def __init__(self, name: str, args: argparse.Namespace) -> None:
        import rllib_asor
        from rllib_asor.algorithms.sac.fast import fast_off_policy

        config = sac_config(args)
        if name == "rllib":
            config = fast_off_policy(config)
        elif name == "asor":
            config = rllib_asor.with_asor(fast_off_policy(config), seed=args.seed)
        elif name == "asor_every_step":
            config = rllib_asor.with_asor(fast_off_policy(config), seed=args.seed, aux_epochs=1)
        elif name == "asor_stock":
            config = rllib_asor.with_asor(fast_off_policy(config, enabled=False), seed=args.seed)
        self.algo = config.build_algo()
        self.steps = 0
        self.updates = 0

    def run(self, steps: int) -> int:
        target = self.steps + steps
        while self.steps < target:
            result = self.algo.train()
            self.steps = int(result["num_env_steps_sampled_lifetime"])
        return self.steps

    def stop(self) -> None:
        self.algo.stop()


def make_runner(name: str, args: argparse.Namespace) -> Any:
    return Sb3Runner(args) if name == "sb3" else RllibRunner(name, args)


def measure(args: argparse.Namespace) -> dict[str, Any]:
    """Warm every runner up, then time interleaved blocks; env steps/s per runner."""
    runners = {}
    for name in args.runners:
        t0 = time.perf_counter()
        runners[name] = make_runner(name, args)
        runners[name].run(args.warmup)
        print(f"{name}: built + {args.warmup} warm-up steps in {time.perf_counter() - t0:.1f}s")
    rounds = time_interleaved(
        runners, args.rounds, lambda n: args.stock_block if n.endswith("_stock") else args.block
    )
    for runner in runners.values():
        runner.stop()
    rates = {
        n: sum(x["steps"] for x in rs) / sum(x["wall_s"] for x in rs) for n, rs in rounds.items()
    }
    ratios, paired = {}, {}
    for base in ("sb3", "rllib_stock"):
        if base in rates:
            ratios[f"vs_{base}"] = {n: v / rates[base] for n, v in rates.items()}
            # per round, each runner against the base's block of the same round
            paired[f"vs_{base}"] = median_paired_ratios(rounds, base)
    return {
        "env": ENV_ID,
        "settings": {
            "warmup": args.warmup,
            "block": args.block,
            "stock_block": args.stock_block,
            "rounds": args.rounds,
            "seed": args.seed,
            "batch": 256,
            "hidden": [256, 256],
            "updates_per_env_step": 1,
        },
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version()},
        "env_steps_per_s": rates,
        "per_round": rounds,
        "ratios": ratios,
        "median_paired_ratios": paired,
        "load_avg_after": os.getloadavg(),
        "versions": _versions(),
    }


def _versions() -> dict[str, str]:
    import ray
    import torch

    out = {"ray": ray.__version__, "torch": torch.__version__}
    try:
        import stable_baselines3

        out["stable_baselines3"] = stable_baselines3.__version__
    except ImportError:
        pass
    return out


def table(res: dict[str, Any]) -> str:
    rates = res["env_steps_per_s"]
    sb3 = rates.get("sb3")
    stock = rates.get("rllib_stock")
    paired = res.get("median_paired_ratios", {}).get("vs_sb3", {})
    lines = [
        "| runner | env steps/s while learning | per round | ÷ SB3 | ÷ SB3, median of rounds "
        "| ÷ RLlib stock |",
        "|---|---|---|---|---|---|",
    ]
    for name, rate in rates.items():
        per = ", ".join(f"{x['steps_per_s']:.1f}" for x in res["per_round"][name])
        vs_sb3 = f"{rate / sb3:.2f}" if sb3 else "–"
        med = f"{paired[name]:.2f}" if name in paired else "–"
        vs_stock = f"{rate / stock:.2f}" if stock else "–"
        lines.append(f"| {LABELS[name]} | {rate:.1f} | {per} | {vs_sb3} | {med} | {vs_stock} |")
    return "\n".join(lines) + "\n"


def profile(name: str, args: argparse.Namespace) -> None:
    import cProfile
    import pstats

    runner = make_runner(name, args)
    runner.run(args.warmup)
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    runner.run(args.block)
    prof.disable()
    wall = time.perf_counter() - t0
    runner.stop()
    print(f"{name}: {args.block} steps in {wall:.1f}s = {args.block / wall:.1f} steps/s (profiled)")
    stats = pstats.Stats(prof).sort_stats("cumulative")
    stats.print_stats(args.profile_lines)
    if args.out:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        stats.dump_stats(str(Path(args.out) / f"profile-{name}.pstats"))


def cql_update_speed(args: argparse.Namespace) -> dict[str, Any]:
    """CQL Learner gradient steps/s on random Hopper-shaped batches (no dataset needed): RLlib's
    module vs the fast path's concat-MLP critics, with and without ASOR, interleaved rounds.
    Offline batches come through Ray Data, so the critics are the part of the fast path CQL
    gets; this measures the Learner step alone."""
    import gymnasium as gym
    import torch
    from ray.rllib.algorithms.cql import CQLConfig
    from ray.rllib.core.columns import Columns

    import rllib_asor
    import rllib_asor.envs  # noqa: F401
    from rllib_asor.algorithms.sac.fast import fast_off_policy

    env = gym.make(ENV_ID)
    base = (
        CQLConfig()
        .environment(ENV_ID)
        .env_runners(num_env_runners=0)
        .learners(num_learners=0)
        .training(
            train_batch_size_per_learner=256,
            lr=None,
            actor_lr=1e-4,
            critic_lr=3e-4,
            alpha_lr=1e-4,
            bc_iters=0,
            min_q_weight=5.0,
        )
        .rl_module(model_config=MUJOCO_SAC_MODEL)
        .debugging(seed=args.seed)
    )
    variants = {
        "cql_stock": base,
        "cql": fast_off_policy(base),
        "cql_asor_stock": rllib_asor.with_asor(fast_off_policy(base, enabled=False), seed=0),
        "cql_asor": rllib_asor.with_asor(base, seed=0),
    }
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(256, *env.observation_space.shape)).astype(np.float32)
    batch = {
        Columns.OBS: obs,
        Columns.NEXT_OBS: obs + 0.01,
        Columns.ACTIONS: rng.uniform(-1, 1, (256, *env.action_space.shape)).astype(np.float32),
        Columns.REWARDS: rng.normal(size=256).astype(np.float32),
        Columns.TERMINATEDS: np.zeros(256, dtype=bool),
        Columns.TRUNCATEDS: np.zeros(256, dtype=bool),
    }
    learners = {n: c.build_learner(env=env) for n, c in variants.items()}
    times: dict[str, list[float]] = {n: [] for n in learners}
    for _ in range(args.rounds):
        for name, learner in learners.items():
            t0 = time.perf_counter()
            for _ in range(args.cql_updates):
                tb = {"default_policy": {k: torch.from_numpy(v.copy()) for k, v in batch.items()}}
                learner._update(tb)
            times[name].append(args.cql_updates / (time.perf_counter() - t0))
    rates = {n: float(np.mean(v)) for n, v in times.items()}
    out = {"updates_per_s": rates, "per_round": times, "updates_per_round": args.cql_updates}
    print("| CQL Learner (batch 256, 256x256) | gradient steps/s | per round |")
    print("|---|---|---|")
    for n, r in rates.items():
        print(f"| {n} | {r:.1f} | {', '.join(f'{x:.1f}' for x in times[n])} |")
    return out


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--runners", nargs="+", choices=[*RUNNERS, "none"], default=list(RUNNERS))
    p.add_argument("--warmup", type=int, default=1000, help="env steps before learning")
    p.add_argument("--block", type=int, default=256, help="env steps per runner and round")
    p.add_argument(
        "--stock-block", type=int, default=128, help="env steps per round of the *_stock runners"
    )
    p.add_argument("--rounds", type=int, default=8)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="benchmarks/out/sac_speed")
    p.add_argument("--profile", choices=RUNNERS, default=None)
    p.add_argument("--profile-lines", type=int, default=45)
    p.add_argument(
        "--cql-updates",
        type=int,
        default=0,
        help="also time N CQL Learner steps per variant and round (writes cql_speed.json)",
    )
    args = p.parse_args(argv)

    from benchmarks.common import start_local_ray, write_json

    if "sb3" in args.runners or args.profile == "sb3":
        try:
            import stable_baselines3  # noqa: F401
        except ImportError:
            p.error('runner sb3 needs Stable-Baselines3: pip install -e ".[bench]"')
    start_local_ray(2)
    if args.profile:
        profile(args.profile, args)
        return
    if args.cql_updates:
        write_json(Path(args.out) / "cql_speed.json", cql_update_speed(args))
        if args.runners == ["none"]:
            return
    res = measure(args)
    md = table(res)
    res["table_md"] = md
    write_json(Path(args.out) / "sac_speed.json", res)
    print(md)


if __name__ == "__main__":
    main()
