"""The paper's Walker2d figure: env reward vs ASOR-augmented reward along episodes that fall.

Trains SAC+ASOR briefly on `rllib_asor/Walker2dShift-v0` (mass/damping/wind per episode; the
tuned example's ASOR block: λ = 0.05, log form, ρ1 = ρ2 = 0.5, RND), then runs its policy under
the original dynamics until the walker falls (`terminated`), and records per step the env
reward r_t and the augmented reward r_t + λ·log ω(s_t) from the trained discriminator.
The paper's claim: the augmented reward drops on the states just before the fall while the env
reward does not. We test it on every falling episode: mean λ·log ω(s) over the last `--window`
steps before the fall vs the steps before them, and the same for the env reward.

    python -m studies.lib.walker_figure --steps 4000 --episodes 10 \
        --out studies/out/walker_figure --png docs/walker_augmented_reward.png
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from studies.lib.common import start_local_ray
from studies.lib.mujoco_shift import train

ASOR = {
    "preset": "paper",  # the form these results were measured with
    "mode": "asor",
    "proxy": "rnd",
    "rho_value": 0.5,
    "rho_count": 0.5,
    "lambda_": 0.05,
    "reward_form": "log",
}


def rollouts(algo, episodes: int, explore: bool, seed: int = 3000) -> list[dict]:
    """Episodes under the original dynamics with per-step env reward and log ω(s_t)."""
    import torch

    from rllib_asor.asor.reward import reward_bonus
    from rllib_asor.evaluation.rollout import module_actor, rollout

    disc = algo.learner_group._learner.module["asor_disc.default_policy"].unwrapped().trainer.state
    policy = module_actor(algo.get_module(), explore=explore)()
    states: list[list[np.ndarray]] = []
    rewards: list[list[float]] = []

    def actor():  # the module's step, keeping each episode's states
        states.append([])
        rewards.append([])

        def step(obs, info):
            states[-1].append(np.asarray(obs, dtype=np.float32))
            return policy(obs, info)

        return step

    done = rollout(
        actor, "rllib_asor/Walker2dShift-v0", episodes, seed=seed,
        env_kwargs={"dynamics": "original"}, watch=lambda ep, a, r, info: rewards[ep].append(r),
    )  # fmt: skip
    eps = []
    for s, r, ep in zip(states, rewards, done.episodes, strict=True):
        with torch.no_grad():
            log_omega = reward_bonus(disc.disc(torch.as_tensor(np.stack(s))), "log", -5.0)
        eps.append({"rewards": r, "log_omega": log_omega.numpy().tolist(), "fell": ep.terminated})
    return eps


def drop_stats(eps: list[dict], lam: float, window: int) -> dict:
    """Per falling episode: mean over the last `window` steps minus mean over earlier steps."""
    rows = []
    for e in eps:
        r, b = np.array(e["rewards"]), lam * np.array(e["log_omega"])
        if not e["fell"] or len(r) < 2 * window:
            continue
        rows.append(
            {
                "length": len(r),
                "bonus_before": float(b[:-window].mean()),
                "bonus_last": float(b[-window:].mean()),
                "env_before": float(r[:-window].mean()),
                "env_last": float(r[-window:].mean()),
            }
        )
    if not rows:
        return {"episodes": 0}
    d_bonus = np.array([x["bonus_last"] - x["bonus_before"] for x in rows])
    d_env = np.array([x["env_last"] - x["env_before"] for x in rows])
    return {
        "episodes": len(rows),
        "window": window,
        "per_episode": rows,
        "bonus_drop_mean": float(d_bonus.mean()),
        "bonus_dropped_in": int((d_bonus < 0).sum()),
        "env_drop_mean": float(d_env.mean()),
        "env_dropped_in": int((d_env < 0).sum()),
    }


def plot(ep: dict, lam: float, window: int, png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = np.array(ep["rewards"])
    b = lam * np.array(ep["log_omega"])
    t = np.arange(len(r))
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(6, 4.2), sharex=True)
    ax1.plot(t, r, label="env reward r_t", color="tab:blue")
    ax1.plot(t, r + b, label="augmented r_t + λ·log ω(s_t)", color="tab:red")
    ax1.axvspan(len(r) - window, len(r) - 1, color="grey", alpha=0.2, label=f"last {window} steps")
    ax1.set_ylabel("reward")
    ax1.legend(fontsize=7, loc="lower left")
    ax1.set_title(
        f"Walker2d (original dynamics), one episode ending in a fall at step {len(r)}", fontsize=9
    )
    ax2.plot(t, b, color="tab:red")
    ax2.axvspan(len(r) - window, len(r) - 1, color="grey", alpha=0.2)
    ax2.set_ylabel(f"λ·log ω(s)  (λ={lam})", fontsize=8)
    ax2.set_xlabel("step")
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=80)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--steps", type=int, default=4000)
    p.add_argument("--learning-starts", type=int, default=1000)
    p.add_argument("--utd", type=float, default=0.25)
    p.add_argument("--iter-steps", type=int, default=500)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--window", type=int, default=10)
    p.add_argument("--explore", action="store_true", help="sample actions (default: deterministic)")
    p.add_argument("--out", default="studies/out/walker_figure")
    p.add_argument("--png", default="docs/walker_augmented_reward.png")
    args = p.parse_args(argv)
    import ray

    import rllib_asor.envs  # noqa: F401  (registers the env ids for the local env runner)

    start_local_ray(2)
    algo, curve, stats, wall = train("Walker2d", args.seed, ASOR, args)
    try:
        eps = rollouts(algo, args.episodes, args.explore)
        if not any(e["fell"] for e in eps):  # a deterministic policy may stand: sample instead
            eps += rollouts(algo, args.episodes, True, seed=4000)
    finally:
        algo.stop()
        ray.shutdown()
    lam = ASOR["lambda_"]
    stats_drop = drop_stats(eps, lam, args.window)
    falling = [e for e in eps if e["fell"] and len(e["rewards"]) >= 2 * args.window]
    if falling:
        plot(max(falling, key=lambda e: len(e["rewards"])), lam, args.window, Path(args.png))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    res = {
        "train_steps": curve[-1][0],
        "train_wall_s": wall,
        "curve": curve,
        "asor_last": stats,
        "lambda_": lam,
        "drop": stats_drop,
        "episodes": eps,
        "png": args.png if falling else None,
    }
    (out / "result.json").write_text(json.dumps(res))
    print(json.dumps({k: v for k, v in res.items() if k not in ("episodes", "curve")}, indent=1))


if __name__ == "__main__":
    main()
