"""Off-policy speed side by side, one process, one torch thread: every ratio of the speed targets.

Online runners, env steps/s while learning on `rllib_asor/Walker2dShift-v0` (40 gravity tasks:
ESCP needs `info["dynamics_id"]`; every runner gets the same env), one local env, batch 256,
γ 0.99, τ 0.005, a 100k replay, `--warmup` random steps, then **one gradient step per env
step** for all (the same update-to-data ratio):

- `sb3`: Stable-Baselines3 `SAC` (256x256), train_freq 1, gradient_steps 1;
- `plain`: a CleanRL-style torch SAC loop written here (`PlainSac`: numpy replay, 256x256 twin
  critics, one update per env step; the floor of what Python + torch costs per step);
- `fast_sac`: RLlib SAC on the fast path (`fast_off_policy`, what `FastSACConfig` builds);
- `sac_asor`: `with_asor(SACConfig...)` (fast path by default);
- `escp`, `escp_asor`: `EscpConfig()` (its 128-64 nets, GRU encoder over 16 steps, RMDM on from
  the first update: ESCP's steady state) and `with_asor` of it;
- `escp_asor_task_mean`: ESCP+ASOR whose value pass feeds π the critics' per-task z̄ instead
  of the window's z (`EscpTorchRLModule.state_values(context="task_mean")`: no encoder pass).

Learner runners (`--learner-steps` > 0), gradient steps/s of the Learner's `_update` on fixed
random Hopper-shaped batches (MAPLE is offline: no env): `fast_sac_learner` (256 transitions),
`maple` and `maple_asor` (256 segments of h = 10 steps, `benchmarks.maple_speed`'s batch).

Runners are timed in interleaved rounds after their warm-up (load drift hits all alike); each
ratio is the median over rounds of the two runners' rates in the same round. Run:

    nice -n 5 .venv/bin/python -m benchmarks.offpolicy_speed --quick

(`--quick`: 3 rounds of 128 steps, 600 warm-up steps). `--breakdown` also times where a
gradient step goes (forward, losses, backward, optimizer; ESCP's encoder passes) for fast SAC
and ESCP on a fixed batch. Writes OUT/offpolicy_speed.json and prints markdown tables.
"""

from __future__ import annotations

import argparse
import copy
import os
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import median_paired_ratios, start_local_ray, time_interleaved, write_json
from benchmarks.escp_speed import RllibRunner, escp_config

ENV_ID = "rllib_asor/Walker2dShift-v0"
ENV_CONFIG = {"params": ["gravity"], "num_tasks": 40, "task_seed": 0}
ONLINE = ("sb3", "plain", "fast_sac", "sac_asor", "escp", "escp_asor", "escp_asor_task_mean")
LEARNER = ("fast_sac_learner", "maple", "maple_asor")
LABELS = {
    "sb3": "Stable-Baselines3 `SAC` (256x256)",
    "plain": "plain CleanRL-style torch SAC loop (256x256; the floor)",
    "fast_sac": "fast SAC (`fast_off_policy`/`FastSACConfig`, 256x256)",
    "sac_asor": "SAC + ASOR (`with_asor`, fast path)",
    "escp": "ESCP (`EscpConfig()`: 128-64 nets, GRU encoder over 16 steps)",
    "escp_asor": "ESCP + ASOR (`with_asor(EscpConfig())`)",
    "escp_asor_task_mean": "ESCP + ASOR, value pass with z̄_task for π",
    "fast_sac_learner": "fast SAC Learner step (256 transitions)",
    "maple": "MAPLE Learner step (256 segments × 10)",
    "maple_asor": "MAPLE + ASOR Learner step",
}
TARGETS = [  # (ratio name, runner, base, target: ratio ≥ target)
    ("fast SAC ÷ SB3", "fast_sac", "sb3", 1.2),
    ("SAC+ASOR ÷ SB3", "sac_asor", "sb3", 1.0),
    ("ESCP ÷ fast SAC", "escp", "fast_sac", 0.7),
    ("ESCP+ASOR ÷ fast SAC", "escp_asor", "fast_sac", 0.6),
    ("ESCP+ASOR (z̄ value pass) ÷ fast SAC", "escp_asor_task_mean", "fast_sac", 0.6),
    ("plain loop ÷ SB3", "plain", "sb3", None),
    ("fast SAC ÷ plain loop", "fast_sac", "plain", None),
    ("MAPLE step ÷ fast SAC step", "maple", "fast_sac_learner", None),
    ("MAPLE+ASOR step ÷ MAPLE step", "maple_asor", "maple", None),
]


def fast_sac_config(args: argparse.Namespace, env_id: str, env_config: dict[str, Any]) -> Any:
    """`benchmarks.sac_speed.sac_config`'s settings on the fast path: `FastSACConfig` where
    the package has it (`with_asor` keeps the config's path), else `fast_off_policy`."""
    import rllib_asor
    from benchmarks.sac_speed import sac_config
    from rllib_asor.algorithms.sac.fast import fast_off_policy

    config_class = getattr(rllib_asor, "FastSACConfig", None)
    if config_class is not None:
        return sac_config(args, env_id, env_config, config_class)
    return fast_off_policy(sac_config(args, env_id, env_config))


class PlainSac:
    """SAC as CleanRL's `sac_continuous_action.py` writes it, with SB3's and RLlib's rhythm
    (actor, critics and α updated every env step): numpy replay, 256x256 ReLU MLPs, twin
    critics in one Adam, Polyak targets, automatic entropy (target −|A|, initial α 1)."""

    def __init__(self, args: argparse.Namespace, env_id: str = ENV_ID, env_config: Any = None):
        import gymnasium as gym
        import torch
        from torch import nn

        import rllib_asor.envs  # noqa: F401

        torch.manual_seed(args.seed)
        self.torch, self.args = torch, args
        self.env = gym.make(env_id, **(env_config or ENV_CONFIG))
        obs_dim = int(np.prod(self.env.observation_space.shape))
        act_dim = int(np.prod(self.env.action_space.shape))
        low, high = self.env.action_space.low, self.env.action_space.high
        self.scale = torch.tensor((high - low) / 2, dtype=torch.float32)
        self.bias = torch.tensor((high + low) / 2, dtype=torch.float32)

        def mlp(i: int, o: int) -> nn.Module:
            return nn.Sequential(
                nn.Linear(i, 256), nn.ReLU(), nn.Linear(256, 256), nn.ReLU(), nn.Linear(256, o)
            )

        self.actor = mlp(obs_dim, 2 * act_dim)
        self.qf1, self.qf2 = mlp(obs_dim + act_dim, 1), mlp(obs_dim + act_dim, 1)
        self.qf1_t, self.qf2_t = copy.deepcopy(self.qf1), copy.deepcopy(self.qf2)
        self.q_opt = torch.optim.Adam([*self.qf1.parameters(), *self.qf2.parameters()], lr=3e-4)
        self.a_opt = torch.optim.Adam(self.actor.parameters(), lr=3e-4)
        self.log_alpha = torch.zeros(1, requires_grad=True)
        self.alpha_opt = torch.optim.Adam([self.log_alpha], lr=3e-4)
        self.target_entropy = -float(act_dim)
        cap = 100_000
        self.buf = {
            "obs": np.zeros((cap, obs_dim), np.float32),
            "next": np.zeros((cap, obs_dim), np.float32),
            "act": np.zeros((cap, act_dim), np.float32),
            "rew": np.zeros(cap, np.float32),
            "done": np.zeros(cap, np.float32),
        }
        self.cap, self.size, self.pos = cap, 0, 0
        self.rng = np.random.default_rng(args.seed)
        self.obs, _ = self.env.reset(seed=args.seed)
        self.steps = 0

    def _policy(self, obs: Any) -> tuple[Any, Any]:
        torch = self.torch
        mean, log_std = self.actor(obs).chunk(2, -1)
        log_std = -5 + 3.5 * (torch.tanh(log_std) + 1)  # CleanRL's [−5, 2]
        std = log_std.exp()
        x = mean + std * torch.randn_like(mean)
        y = torch.tanh(x)
        logp = (-0.5 * ((x - mean) / std) ** 2 - log_std - 0.5 * np.log(2 * np.pi)).sum(-1)
        logp = logp - torch.log(self.scale * (1 - y.pow(2)) + 1e-6).sum(-1)
        return y * self.scale + self.bias, logp

    def _update(self) -> None:
        torch, b = self.torch, self.buf
        idx = self.rng.integers(0, self.size, 256)
        obs, nxt = torch.from_numpy(b["obs"][idx]), torch.from_numpy(b["next"][idx])
        act, rew = torch.from_numpy(b["act"][idx]), torch.from_numpy(b["rew"][idx])
        done = torch.from_numpy(b["done"][idx])
        alpha = self.log_alpha.exp().detach()
        with torch.no_grad():
            a2, logp2 = self._policy(nxt)
            x2 = torch.cat([nxt, a2], -1)
            q_t = torch.min(self.qf1_t(x2), self.qf2_t(x2)).squeeze(-1) - alpha * logp2
            target = rew + 0.99 * (1 - done) * q_t
        x = torch.cat([obs, act], -1)
        q_loss = ((self.qf1(x).squeeze(-1) - target) ** 2).mean() + (
            (self.qf2(x).squeeze(-1) - target) ** 2
        ).mean()
        self.q_opt.zero_grad()
        q_loss.backward()
        self.q_opt.step()
        a_new, logp = self._policy(obs)
        xn = torch.cat([obs, a_new], -1)
        a_loss = (alpha * logp - torch.min(self.qf1(xn), self.qf2(xn)).squeeze(-1)).mean()
        self.a_opt.zero_grad()
        a_loss.backward()
        self.a_opt.step()
        alpha_loss = (-self.log_alpha.exp() * (logp.detach() + self.target_entropy)).mean()
        self.alpha_opt.zero_grad()
        alpha_loss.backward()
        self.alpha_opt.step()
        with torch.no_grad():
            for net, tgt in ((self.qf1, self.qf1_t), (self.qf2, self.qf2_t)):
                for p, tp in zip(net.parameters(), tgt.parameters(), strict=True):
                    tp.data.copy_(0.005 * p.data + 0.995 * tp.data)

    def run(self, steps: int) -> int:
        torch = self.torch
        for _ in range(steps):
            if self.steps < self.args.warmup:
                action = self.env.action_space.sample()
            else:
                with torch.no_grad():
                    action = self._policy(torch.from_numpy(self.obs[None].astype(np.float32)))[0]
                action = action[0].numpy()
            nxt, rew, term, trunc, _ = self.env.step(action)
            b, i = self.buf, self.pos
            b["obs"][i], b["next"][i], b["act"][i] = self.obs, nxt, action
            b["rew"][i], b["done"][i] = rew, float(term)
            self.pos, self.size = (i + 1) % self.cap, min(self.size + 1, self.cap)
            self.obs = self.env.reset()[0] if term or trunc else nxt
            self.steps += 1
            if self.steps > self.args.warmup:
                self._update()
        return self.steps

    def stop(self) -> None:
        self.env.close()


class AlgoRunner(RllibRunner):
    """An RLlib algorithm stepped with `algo.train()` until a step target (escp_speed's
    runner's `run` and `stop`, with this benchmark's algorithms)."""

    def __init__(self, name: str, args: argparse.Namespace) -> None:
        import rllib_asor

        if name in ("fast_sac", "sac_asor"):
            config = fast_sac_config(args, ENV_ID, ENV_CONFIG)
            if name == "sac_asor":
                config = rllib_asor.with_asor(config, seed=args.seed)
        elif name == "escp":
            config = escp_config(args)
        else:
            config = rllib_asor.with_asor(escp_config(args), seed=args.seed)
        self.algo = config.build_algo()
        if name == "escp_asor_task_mean":
            for module in self.algo.learner_group._learner.module.values():
                if hasattr(module.unwrapped(), "task_mean_context"):
                    module.unwrapped().value_context = "task_mean"
        self.steps = 0


class LearnerRunner:
    """A Learner's `_update` on one fixed random batch; `steps` counts gradient steps."""

    def __init__(self, name: str, args: argparse.Namespace) -> None:
        import gymnasium as gym
        import torch
        from ray.rllib.core.columns import Columns

        import rllib_asor
        from benchmarks.maple_speed import ACT, BATCH, OBS, _maple_batch
        from benchmarks.maple_speed import ENV_ID as HOPPER

        self.torch = torch
        rng = np.random.default_rng(args.seed)
        env = gym.make(HOPPER)
        if name == "fast_sac_learner":
            config = fast_sac_config(args, HOPPER, {})
            config.training(train_batch_size_per_learner=BATCH)
            obs = rng.normal(size=(BATCH, OBS)).astype(np.float32)
            self.batch = {
                Columns.OBS: obs,
                Columns.NEXT_OBS: obs + 0.01,
                Columns.ACTIONS: rng.uniform(-1, 1, (BATCH, ACT)).astype(np.float32),
                Columns.REWARDS: rng.normal(size=BATCH).astype(np.float32),
                Columns.TERMINATEDS: np.zeros(BATCH, bool),
                Columns.TRUNCATEDS: np.zeros(BATCH, bool),
                "n_step": np.ones(BATCH, np.int64),
                "weights": np.ones(BATCH, np.float32),
            }
        else:
            config = (
                rllib_asor.MapleConfig()
                .environment(HOPPER)
                .offline_data(input_=["unused"])
                .debugging(seed=args.seed)
            )
            if name == "maple_asor":
                config = rllib_asor.with_asor(config, seed=args.seed)
            self.batch = _maple_batch(10, 128, rng)
        self.learner = config.build_learner(env=env)
        self.steps = 0

    def run(self, steps: int) -> int:
        for _ in range(steps):
            tb = {
                "default_policy": {
                    k: self.torch.from_numpy(v.copy()) for k, v in self.batch.items()
                }
            }
            self.learner._update(tb)
            self.steps += 1
        return self.steps

    def stop(self) -> None:
        pass


def _build(name: str, args: argparse.Namespace) -> Any:
    if name == "sb3":
        from benchmarks.sac_speed import Sb3Runner

        return Sb3Runner(args, ENV_ID, ENV_CONFIG)
    if name == "plain":
        return PlainSac(args)
    if name in LEARNER:
        return LearnerRunner(name, args)
    return AlgoRunner(name, args)


def measure(args: argparse.Namespace) -> dict[str, Any]:
    names = [n for n in args.runners if n in ONLINE]
    if "sb3" in names:
        try:
            import stable_baselines3  # noqa: F401
        except ImportError:
            print('sb3: skipped (pip install "torch==2.13.0" -e ".[bench]")')
            names.remove("sb3")
    out: dict[str, Any] = {"rounds": {}}
    groups = [(names, args.block, args.warmup + args.block)]
    lnames = [n for n in args.runners if n in LEARNER]
    if lnames and args.learner_steps:
        groups.append((lnames, args.learner_steps, 5))
    for group, block, warm in groups:
        runners = {}
        for name in group:
            t0 = time.perf_counter()
            runners[name] = _build(name, args)
            runners[name].run(warm)
            print(f"{name}: built + warm-up in {time.perf_counter() - t0:.1f}s", flush=True)
        out["rounds"].update(time_interleaved(runners, args.rounds, lambda _, b=block: b))
        for runner in runners.values():
            runner.stop()
    rounds = out["rounds"]
    out["steps_per_s"] = {
        n: sum(x["steps"] for x in rs) / sum(x["wall_s"] for x in rs) for n, rs in rounds.items()
    }
    ratios = {}
    for label, a, b, target in TARGETS:
        if a in rounds and b in rounds:
            r = median_paired_ratios({a: rounds[a], b: rounds[b]}, b)[a]
            ratios[label] = {
                "ratio": r,
                "target": target,
                "met": None if target is None else r >= target,
            }
    if "sac_asor" in rounds and "fast_sac" in rounds:  # time share of ASOR in a SAC+ASOR step
        r = median_paired_ratios({"a": rounds["sac_asor"], "s": rounds["fast_sac"]}, "s")["a"]
        ratios["ASOR share of a SAC+ASOR step"] = {
            "ratio": 1 - r,
            "target": 0.15,
            "met": 1 - r <= 0.15,
        }
    out["ratios"] = ratios
    out["settings"] = {k: v for k, v in vars(args).items()}
    out["env"], out["env_config"] = ENV_ID, ENV_CONFIG
    out["machine"] = {"cpus": os.cpu_count(), "python": platform.python_version()}
    out["load_avg_after"] = os.getloadavg()
    return out


def breakdown(args: argparse.Namespace) -> dict[str, dict[str, float]]:
    """ms per gradient step of each part of the Learner's `_update` on a fixed batch: fast SAC
    (256 transitions, Hopper) and ESCP (256 windows of 16 steps, Walker2d, RMDM on), and ESCP's
    encoder alone: a no-grad pass (the target's window, the value pass) and a pass with its
    RMDM backward."""
    import gymnasium as gym
    import torch
    from ray.rllib.core.columns import Columns

    from rllib_asor.algorithms.escp.replay import DYNAMICS_ID, NEXT_WINDOW, WINDOW

    n = args.breakdown_steps
    sac = LearnerRunner("fast_sac_learner", args)
    out = {"fast_sac": _time_parts(sac.learner, lambda: _tensors(sac.batch, torch), n)}
    env = gym.make(ENV_ID, **ENV_CONFIG)
    learner = escp_config(args).build_learner(env=env)
    learner.before_gradient_based_update(timesteps={"num_env_steps_sampled_lifetime": 10**7})
    rng = np.random.default_rng(args.seed)
    od, ad, b = env.observation_space.shape[0], env.action_space.shape[0], 256
    obs = rng.normal(size=(b, od)).astype(np.float32)
    batch = {
        Columns.OBS: obs,
        Columns.NEXT_OBS: obs + 0.01,
        Columns.ACTIONS: rng.uniform(-1, 1, (b, ad)).astype(np.float32),
        Columns.REWARDS: rng.normal(size=b).astype(np.float32),
        Columns.TERMINATEDS: np.zeros(b, bool),
        Columns.TRUNCATEDS: np.zeros(b, bool),
        "n_step": np.ones(b, np.int64),
        "weights": np.ones(b, np.float32),
        WINDOW: rng.normal(size=(b, 16, od + ad)).astype(np.float32),
        NEXT_WINDOW: rng.normal(size=(b, 16, od + ad)).astype(np.float32),
        DYNAMICS_ID: rng.integers(0, 40, b),
    }
    out["escp"] = _time_parts(learner, lambda: _tensors(batch, torch), n)
    module = learner.module["default_policy"].unwrapped()
    window = torch.from_numpy(batch[WINDOW])
    t0 = time.perf_counter()
    with torch.no_grad():
        for _ in range(n):
            module.context(window)
    no_grad = (time.perf_counter() - t0) / n * 1e3
    t0 = time.perf_counter()
    for _ in range(n):
        module.context(window).sum().backward()
    with_bwd = (time.perf_counter() - t0) / n * 1e3
    out["escp_encoder"] = {"no_grad_pass": no_grad, "pass_with_backward": with_bwd}
    return out


def _tensors(batch: dict[str, np.ndarray], torch: Any) -> dict[str, Any]:
    return {"default_policy": {k: torch.from_numpy(v.copy()) for k, v in batch.items()}}


def _time_parts(learner: Any, batch: dict[str, Any], n: int) -> dict[str, float]:
    """Wraps the Learner's forward, losses, gradients and optimizer step with timers."""
    parts = {"forward": 0.0, "losses": 0.0, "backward": 0.0, "optimizer": 0.0}
    names = {
        "forward": ("module", "forward_train"),
        "losses": (None, "compute_losses"),
        "backward": (None, "compute_gradients"),
        "optimizer": (None, "apply_gradients"),
    }
    originals = {}
    for part, (owner, meth) in names.items():
        obj = learner.module if owner else learner
        fn = getattr(obj, meth)
        originals[part] = (obj, meth)

        def timed(*a: Any, _fn: Any = fn, _part: str = part, **k: Any) -> Any:
            t0 = time.perf_counter()
            try:
                return _fn(*a, **k)
            finally:
                parts[_part] += time.perf_counter() - t0

        setattr(obj, meth, timed)
    t0 = time.perf_counter()
    for _ in range(n):
        learner._update(batch())
    total = time.perf_counter() - t0
    for obj, meth in originals.values():
        obj.__dict__.pop(meth, None)
    out = {k: v / n * 1e3 for k, v in parts.items()}
    out["total"] = total / n * 1e3
    out["other"] = out["total"] - sum(v for k, v in out.items() if k != "total")
    return out


def table(res: dict[str, Any]) -> str:
    rates = res["steps_per_s"]
    lines = [
        "| runner | steps/s (env steps; Learner rows: gradient steps) | per round |",
        "|---|---|---|",
    ]
    for name, rate in rates.items():
        per = ", ".join(f"{x['steps_per_s']:.1f}" for x in res["rounds"][name])
        lines.append(f"| {LABELS[name]} | {rate:.1f} | {per} |")
    lines += [
        "",
        "| ratio (median of rounds, side by side) | measured | target | met |",
        "|---|---|---|---|",
    ]
    for label, r in res["ratios"].items():
        target = "–" if r["target"] is None else f"{'≤' if 'share' in label else '≥'} {r['target']}"
        met = "–" if r["met"] is None else ("yes" if r["met"] else "no")
        lines.append(f"| {label} | {r['ratio']:.2f} | {target} | {met} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--runners", nargs="+", choices=[*ONLINE, *LEARNER], default=[*ONLINE, *LEARNER])
    p.add_argument("--warmup", type=int, default=1000, help="random env steps before learning")
    p.add_argument("--block", type=int, default=256, help="env steps per runner and round")
    p.add_argument(
        "--learner-steps", type=int, default=32, help="Learner steps per round (0: none)"
    )
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--quick", action="store_true", help="3 rounds of 128 steps, 600 warm-up")
    p.add_argument("--breakdown", action="store_true", help="also time the parts of a step")
    p.add_argument("--breakdown-steps", type=int, default=20)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="benchmarks/out/offpolicy_speed")
    args = p.parse_args(argv)
    if args.quick:
        args.rounds, args.block, args.warmup, args.learner_steps = 3, 128, 600, 16
    start_local_ray(2)
    res = measure(args)
    if args.breakdown:
        res["breakdown_ms"] = breakdown(args)
    res["table_md"] = table(res)
    write_json(Path(args.out) / "offpolicy_speed.json", res)
    print(res["table_md"])
    if args.breakdown:
        for name, parts in res["breakdown_ms"].items():
            print(name, " ".join(f"{k} {v:.1f} ms" for k, v in parts.items()))


if __name__ == "__main__":
    main()
