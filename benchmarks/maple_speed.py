"""MAPLE speed side by side, one process, one torch thread, interleaved rounds.

1. **Ensemble training**, samples/s: MOPO's ensemble (7 members, 4×200 swish, Hopper's 11-d
   state and 3-d action, 256 rows per member per step as the port, and 64 and 32) trained with all members in one batched
   network (`GaussianEnsemble.forward`: one `baddbmm` per layer) vs the same networks run one
   member at a time, two ways: `loop_forward` (`looped_forward`: a Python loop of `addmm` per
   member, then the same summed loss, one backward, one AdamW step) and `independent` (seven
   one-member networks holding the same weights, each with its own loss, backward and AdamW
   step: the per-member loop as it is usually written). A sample = one (s, a) row of one member.
2. **Learner gradient steps/s** at batch 256: the project's CQL (fast path, concat-MLP critics,
   as `tuned_examples/offline/cql-hopper.yaml`) and CQL+ASOR on 256 transitions; MAPLE,
   MAPLE+ASOR (paper preset and the robust default) on 256 segments of h = 10 steps (2,560
   state rows: MAPLE's own batch, every step valid — the most a batch costs); MOPO (no context,
   h = 5). Random Hopper-shaped batches, no dataset needed; the Learner's `_update` alone (what
   one SAC/CQL step costs), as `benchmarks/sac_speed.py --cql-updates`.

Rates are summed over rounds; each round runs every variant once (so machine load hits them
alike), and the JSON keeps per-round rates. Run:

    nice -n 5 .venv/bin/python -m benchmarks.maple_speed --rounds 5 --out benchmarks/out/maple_speed

On a GPU machine (the ensemble part alone needs no ray; the Learner part runs on the CPU):

    python -m benchmarks.maple_speed --parts ensemble --device cuda --ensemble-steps 50
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import write_json

ENV_ID = "rllib_asor/HopperShift-v0"
OBS, ACT, BATCH = 11, 3, 256


def ensemble_speed(args: argparse.Namespace) -> dict[str, Any]:
    """Training samples/s of the batched ensemble vs the per-member loops, per rows per member."""
    return {str(rows): _ensemble_speed(args, rows) for rows in args.ensemble_rows}


def _ensemble_speed(args: argparse.Namespace, rows: int) -> dict[str, Any]:
    import torch

    from rllib_asor.algorithms.maple.ensemble import GaussianEnsemble, gaussian_nll, looped_forward

    torch.manual_seed(0)
    k, dev = 7, torch.device(args.device)
    obs = torch.randn(k, rows, OBS, device=dev)
    act = torch.rand(k, rows, ACT, device=dev) * 2 - 1
    target = torch.cat([obs + 0.01 * torch.randn_like(obs), torch.randn_like(obs[..., :1])], -1)
    batched = GaussianEnsemble(OBS, ACT, k, 5, 200, 4).to(dev)
    loop = GaussianEnsemble(OBS, ACT, k, 5, 200, 4).to(dev)
    loop.load_state_dict(batched.state_dict())
    singles = []
    for i in range(k):  # member i of the same weights as a network of its own
        one = GaussianEnsemble(OBS, ACT, 1, 1, 200, 4)
        state = {
            n: (v[i : i + 1] if n.endswith(("weight", "bias")) and v.dim() == 3 else v)
            for n, v in batched.state_dict().items()
        }
        state["elite_idx"] = torch.zeros(1, dtype=torch.long, device=dev)
        one.load_state_dict(state)
        singles.append(one.to(dev))

    def adamw(params: Any) -> Any:
        return torch.optim.AdamW(params, lr=1e-3, weight_decay=7.5e-5)

    opt_b, opt_l = adamw(batched.parameters()), adamw(loop.parameters())
    opt_s = [adamw(m.parameters()) for m in singles]

    def train(model: Any, opt: Any, mu_logstd: Any, tgt: Any) -> None:
        loss = gaussian_nll(*mu_logstd, tgt, model)
        opt.zero_grad()
        loss.backward()
        opt.step()

    steps = {
        "batched": lambda: train(batched, opt_b, batched(obs, act), target),
        "loop_forward": lambda: train(loop, opt_l, looped_forward(loop, obs, act), target),
        "independent": lambda: [
            train(m, o, m(obs[i : i + 1], act[i : i + 1]), target[i : i + 1])
            for i, (m, o) in enumerate(zip(singles, opt_s, strict=True))
        ],
    }

    def sync() -> None:  # a GPU runs asynchronously: time finished work only
        if dev.type == "cuda":
            torch.cuda.synchronize(dev)

    for fn in steps.values():  # warm-up
        for _ in range(3):
            fn()
    per_round: dict[str, list[float]] = {n: [] for n in steps}
    for _ in range(args.rounds):
        for n, fn in steps.items():
            sync()
            t0 = time.perf_counter()
            for _ in range(args.ensemble_steps):
                fn()
            sync()
            per_round[n].append(args.ensemble_steps * k * rows / (time.perf_counter() - t0))
    rates = {n: float(np.mean(v)) for n, v in per_round.items()}
    speedup = {
        n: float(np.median([b / x for b, x in zip(per_round["batched"], v, strict=True)]))
        for n, v in per_round.items()
        if n != "batched"
    }
    return {
        "samples_per_s": rates,
        "per_round": per_round,
        "speedup_median": speedup,
        "steps_per_round": args.ensemble_steps,
        "rows_per_member": rows,
        "device": args.device,
    }


def _maple_batch(h: int, hidden: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    obs = rng.normal(size=(BATCH, h, OBS)).astype(np.float32)
    acts = rng.uniform(-1, 1, (BATCH, h, ACT)).astype(np.float32)
    real = {
        "real_obs": rng.normal(size=(BATCH, OBS)).astype(np.float32),
        "real_next_obs": rng.normal(size=(BATCH, OBS)).astype(np.float32),
        "real_actions": rng.uniform(-1, 1, (BATCH, ACT)).astype(np.float32),
        "real_last_actions": rng.uniform(-1, 1, (BATCH, ACT)).astype(np.float32),
        "real_rewards": rng.normal(size=BATCH).astype(np.float32),
        "real_terminateds": np.zeros(BATCH, bool),
        "real_dynamics_ids": rng.integers(0, 3, BATCH),
        "real_policy_hidden": np.zeros((BATCH, hidden), np.float32),
        "real_value_hidden": np.zeros((BATCH, hidden), np.float32),
    }
    return {
        "obs": obs,
        "actions": acts,
        "next_obs": obs + 0.01,
        "last_actions": np.concatenate([np.zeros_like(acts[:, :1]), acts[:, :-1]], 1),
        "rewards": rng.normal(size=(BATCH, h)).astype(np.float32),
        "terminateds": np.zeros((BATCH, h), bool),
        "valid": np.ones((BATCH, h), bool),
        "policy_hidden": np.zeros((BATCH, hidden), np.float32),
        "value_hidden": np.zeros((BATCH, hidden), np.float32),
        **real,
    }


def learner_speed(args: argparse.Namespace) -> dict[str, Any]:
    """Learner gradient steps/s: CQL (+ASOR) on 256 transitions, MAPLE (+ASOR) and MOPO on 256
    segments."""
    import gymnasium as gym
    import torch
    from ray.rllib.algorithms.cql import CQLConfig
    from ray.rllib.core.columns import Columns

    import rllib_asor
    import rllib_asor.envs  # noqa: F401
    from rllib_asor.algorithms.sac.fast import fast_off_policy
    from rllib_asor.data.collect import MUJOCO_SAC_MODEL

    env = gym.make(ENV_ID)
    cql = fast_off_policy(
        CQLConfig()
        .environment(ENV_ID)
        .env_runners(num_env_runners=0)
        .learners(num_learners=0)
        .training(
            train_batch_size_per_learner=BATCH,
            lr=None,
            actor_lr=1e-4,
            critic_lr=3e-4,
            alpha_lr=1e-4,
            bc_iters=0,
            min_q_weight=5.0,
        )
        .rl_module(model_config=MUJOCO_SAC_MODEL)
        .debugging(seed=0)
    )

    def maple(cls: Any) -> Any:
        return cls().environment(ENV_ID).offline_data(input_=["unused"]).debugging(seed=0)

    variants = {
        "cql": cql,
        "cql_asor": rllib_asor.with_asor(cql, seed=0),
        "maple": maple(rllib_asor.MapleConfig),
        "maple_asor_paper": rllib_asor.with_asor(
            maple(rllib_asor.MapleConfig), preset="paper", lambda_=0.1, seed=0
        ),
        "maple_asor": rllib_asor.with_asor(maple(rllib_asor.MapleConfig), seed=0),
        "mopo": maple(rllib_asor.MopoConfig),
    }
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(BATCH, OBS)).astype(np.float32)
    cql_batch = {
        Columns.OBS: obs,
        Columns.NEXT_OBS: obs + 0.01,
        Columns.ACTIONS: rng.uniform(-1, 1, (BATCH, ACT)).astype(np.float32),
        Columns.REWARDS: rng.normal(size=BATCH).astype(np.float32),
        Columns.TERMINATEDS: np.zeros(BATCH, dtype=bool),
        Columns.TRUNCATEDS: np.zeros(BATCH, dtype=bool),
    }
    batches = {
        "cql": cql_batch,
        "cql_asor": cql_batch,
        "maple": _maple_batch(10, 128, rng),
        "maple_asor_paper": _maple_batch(10, 128, rng),
        "maple_asor": _maple_batch(10, 128, rng),
        "mopo": _maple_batch(5, 0, rng),
    }
    learners = {n: c.build_learner(env=env) for n, c in variants.items()}

    def step(name: str) -> None:
        tb = {"default_policy": {k: torch.from_numpy(v.copy()) for k, v in batches[name].items()}}
        learners[name]._update(tb)

    for name in learners:
        for _ in range(3):
            step(name)
    per_round: dict[str, list[float]] = {n: [] for n in learners}
    for _ in range(args.rounds):
        for name in learners:
            t0 = time.perf_counter()
            for _ in range(args.updates):
                step(name)
            per_round[name].append(args.updates / (time.perf_counter() - t0))
    rates = {n: float(np.mean(v)) for n, v in per_round.items()}
    rel = {
        n: float(np.median([a / c for a, c in zip(v, per_round["cql"], strict=True)]))
        for n, v in per_round.items()
    }
    rows = {n: BATCH * (10 if n.startswith("maple") else 5 if n == "mopo" else 1) for n in rates}
    return {
        "gradient_steps_per_s": rates,
        "per_round": per_round,
        "ratio_to_cql_median": rel,
        "state_rows_per_step": rows,
        "updates_per_round": args.updates,
    }


def table(res: dict[str, Any]) -> str:
    lines = []
    if "ensemble" in res:
        lines += [
            "| ensemble training (7 × 4×200), rows per member | batched | loop_forward "
            "| independent | batched ÷ loop_forward | batched ÷ independent |",
            "|---|---|---|---|---|---|",
        ]
        for rows, e in res["ensemble"].items():
            r, x = e["samples_per_s"], e["speedup_median"]
            lines.append(
                f"| {rows} | {r['batched']:,.0f} | {r['loop_forward']:,.0f} "
                f"| {r['independent']:,.0f} | {x['loop_forward']:.2f}× | {x['independent']:.2f}× |"
            )
    if "learners" in res:
        ls = res["learners"]
        lines += [
            "",
            "| Learner, batch 256 | gradient steps/s | ÷ CQL (median) | state rows per step |",
            "|---|---|---|---|",
            *(
                f"| {n} | {r:.1f} | {ls['ratio_to_cql_median'][n]:.2f} "
                f"| {ls['state_rows_per_step'][n]:,} |"
                for n, r in ls["gradient_steps_per_s"].items()
            ),
        ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--ensemble-steps", type=int, default=20)
    p.add_argument(
        "--ensemble-rows",
        type=int,
        nargs="+",
        default=[256, 64, 32],
        help="rows per member per step (the port trains with 256)",
    )
    p.add_argument("--updates", type=int, default=20)
    p.add_argument(
        "--device",
        default="cpu",
        help="torch device of the ensemble part, e.g. cuda (the Learner part runs on the CPU)",
    )
    p.add_argument(
        "--parts",
        nargs="+",
        choices=["ensemble", "learners"],
        default=["ensemble", "learners"],
        help="what to measure; `ensemble` alone needs no ray",
    )
    p.add_argument("--out", default="benchmarks/out/maple_speed")
    args = p.parse_args(argv)
    import torch

    try:
        dev = torch.device(args.device)
        torch.empty(1, device=dev)
    except (RuntimeError, AssertionError) as err:
        p.error(f"--device {args.device!r} is not usable here ({err}); try cpu or cuda")
    torch.set_num_threads(1)
    res = {
        "machine": {"platform": platform.platform(), "processor": platform.processor()},
        "torch_threads": 1,
        "args": vars(args),
        **({"ensemble": ensemble_speed(args)} if "ensemble" in args.parts else {}),
        **({"learners": learner_speed(args)} if "learners" in args.parts else {}),
    }
    write_json(Path(args.out) / "maple_speed.json", res)
    print(table(res))


if __name__ == "__main__":
    main()
