"""Soak test: PPO+ASOR on the lava world for a long run, resident memory recorded per iteration.

    python benchmarks/soak.py                  # 30 minutes (the acceptance run)
    python benchmarks/soak.py --minutes 2      # a quick check that it works

Trains `PPO` + `with_asor` on `rllib_asor/LavaWorld-v0` with the settings of
`tuned_examples/lava/ppo-asor.yaml` (2 remote EnvRunners at 0.5 CPU, 4 envs each, batch 2000,
6 epochs) in this process (the Learner lives in the driver, `num_learners=0`), with
`with_fault_tolerance` defaults. After every iteration it records the resident set size (RSS,
psutil) of every process of the local Ray session started here: the driver, the EnvRunner
actors, Ray's own daemons (gcs_server, raylet, agents) and idle workers, summed per group, plus
the total unique set size (USS: memory no other process shares, so not double-counting torch
libraries mapped into every process).

The clock starts when the Algorithm is built; at least 3 iterations run. Memory growth is
measured after warm-up: from the first iteration at or after
`--warmup-minutes` (default 5, or a third of a run shorter than 15 minutes) to the mean of the
last 3 iterations, in percent of the warm-up value, for the total RSS and per group; the run
passes if the total grows less than `--max-growth` percent (default 10). A least-squares slope
(MiB per hour) over the same window is reported beside it.

Writes `soak.json`, `soak.md` (summary + per-iteration table) and `soak.png` under `--out`
(default benchmarks/out). Exit status 0 pass, 1 growth over the limit.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

os.environ.setdefault("RAY_memory_monitor_refresh_ms", "0")
os.environ.setdefault("RAY_DISABLE_DOCKER_CPU_WARNING", "1")

import ray  # noqa: E402  (first: it puts Ray's bundled psutil on sys.path)

# isort: split
import psutil  # noqa: E402

MIB = 1024**2
GROUPS = ("driver", "env_runners", "ray_daemons", "other_workers")
MIN_ITERATIONS = 3


# ------------------------------------------------------------------------------ memory probes
def _group(proc: psutil.Process, driver_pid: int) -> str:
    if proc.pid == driver_pid:
        return "driver"
    try:
        title = " ".join(proc.cmdline()) or proc.name()
    except (psutil.NoSuchProcess, psutil.AccessDenied, psutil.ZombieProcess):
        title = ""
    if "EnvRunner" in title:
        return "env_runners"
    if title.startswith("ray::"):
        return "other_workers"  # idle pool workers, other actors (ray::IDLE, ...)
    return "ray_daemons"  # gcs_server, raylet, dashboard/runtime-env agents, log monitor


def memory_snapshot(driver_pid: int | None = None) -> dict[str, Any]:
    """RSS (MiB) per group of the driver and all its descendants, total USS, process counts."""
    driver_pid = driver_pid or os.getpid()
    root = psutil.Process(driver_pid)
    procs = [root, *root.children(recursive=True)]
    rss = dict.fromkeys(GROUPS, 0.0)
    count = dict.fromkeys(GROUPS, 0)
    uss = 0.0
    for proc in procs:
        try:
            group = _group(proc, driver_pid)
            info = proc.memory_full_info()
        except (psutil.NoSuchProcess, psutil.AccessDenied, psutil.ZombieProcess):
            continue
        rss[group] += info.rss / MIB
        uss += getattr(info, "uss", info.rss) / MIB
        count[group] += 1
    return {
        "rss_mib": {g: round(v, 1) for g, v in rss.items()},
        "rss_total_mib": round(sum(rss.values()), 1),
        "uss_total_mib": round(uss, 1),
        "processes": count,
    }


# ------------------------------------------------------------------------------ analysis
def growth(rows: list[dict], warmup_s: float, key: Any) -> dict[str, Any]:
    """Growth of `key(row)` from the first row at/after warm-up to the mean of the last 3."""
    after = [r for r in rows if r["elapsed_s"] >= warmup_s]
    if len(after) < 2:
        return {"start": None, "end": None, "percent": None, "slope_mib_per_h": None,
                "iterations": len(after)}
    start = key(after[0])
    tail = after[-3:]
    end = sum(key(r) for r in tail) / len(tail)
    xs = [r["elapsed_s"] / 3600 for r in after]
    ys = [key(r) for r in after]
    mx, my = sum(xs) / len(xs), sum(ys) / len(ys)
    var = sum((x - mx) ** 2 for x in xs)
    slope = sum((x - mx) * (y - my) for x, y in zip(xs, ys, strict=True)) / var if var else 0.0
    return {"start": round(start, 1), "end": round(end, 1),
            "percent": round(100.0 * (end - start) / start, 2) if start else None,
            "slope_mib_per_h": round(slope, 1), "iterations": len(after)}


def summarize(rows: list[dict], warmup_s: float, max_growth: float) -> dict[str, Any]:
    total = growth(rows, warmup_s, lambda r: r["memory"]["rss_total_mib"])
    per_group = {g: growth(rows, warmup_s, lambda r, g=g: r["memory"]["rss_mib"][g])
                 for g in GROUPS}
    uss = growth(rows, warmup_s, lambda r: r["memory"]["uss_total_mib"])
    ok = total["percent"] is not None and total["percent"] < max_growth
    return {"rss_total": total, "rss_per_group": per_group, "uss_total": uss,
            "max_growth_percent": max_growth, "passed": ok}


# ------------------------------------------------------------------------------ outputs
def verdict(summary: dict) -> str:
    if summary["passed"]:
        return "PASS"
    if summary["rss_total"]["percent"] is None:
        return "NOT MEASURED (fewer than 2 iterations after warm-up)"
    return "FAIL"


def write_markdown(path: Path, meta: dict, rows: list[dict], summary: dict) -> None:
    t = summary["rss_total"]
    lines = [
        "# Soak: PPO+ASOR on the lava world, memory per iteration",
        "",
        f"Command: `{meta['command']}`  ",
        f"Machine: {meta['machine']}; {meta['cpus']} CPUs; Ray {meta['ray']}, "
        f"torch {meta['torch']}  ",
        f"Ran {meta['minutes_run']:.1f} min, {len(rows)} iterations, "
        f"{rows[-1]['num_env_steps_sampled_lifetime'] if rows else 0:.0f} env steps; "
        f"warm-up {meta['warmup_minutes']:.2f} min (the clock starts after the "
        f"{meta.get('build_s', 0):.0f} s build).",
        "",
        f"**Total RSS growth after warm-up: {t['percent']}% "
        f"({t['start']} → {t['end']} MiB, slope {t['slope_mib_per_h']} MiB/h over "
        f"{t['iterations']} iterations); limit {summary['max_growth_percent']:g}%: "
        f"{verdict(summary)}.**",
        "",
        "| group | RSS at warm-up (MiB) | RSS at end (MiB) | growth % | slope MiB/h |",
        "|---|---:|---:|---:|---:|",
    ]
    for g, s in summary["rss_per_group"].items():
        lines.append(f"| {g} | {s['start']} | {s['end']} | {s['percent']} | "
                     f"{s['slope_mib_per_h']} |")
    u = summary["uss_total"]
    lines += [f"| total USS | {u['start']} | {u['end']} | {u['percent']} | "
              f"{u['slope_mib_per_h']} |", ""]
    lines += [
        "| iter | min | env steps | s/iter | return mean | RSS total | driver | env runners "
        "| ray daemons | other workers | USS total | procs |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        m = r["memory"]
        ret = r["episode_return_mean"]
        lines.append(
            f"| {r['iteration']} | {r['elapsed_s'] / 60:.1f} | "
            f"{r['num_env_steps_sampled_lifetime']:.0f} | {r['time_this_iter_s']:.1f} | "
            f"{'n/a' if ret is None else f'{ret:.2f}'} | {m['rss_total_mib']:.0f} | "
            f"{m['rss_mib']['driver']:.0f} | {m['rss_mib']['env_runners']:.0f} | "
            f"{m['rss_mib']['ray_daemons']:.0f} | {m['rss_mib']['other_workers']:.0f} | "
            f"{m['uss_total_mib']:.0f} | {sum(m['processes'].values())} |")
    path.write_text("\n".join(lines) + "\n")


def write_plot(path: Path, rows: list[dict], warmup_s: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    minutes = [r["elapsed_s"] / 60 for r in rows]
    fig, ax = plt.subplots(figsize=(8, 4.5))
    ax.plot(minutes, [r["memory"]["rss_total_mib"] for r in rows], label="RSS total", lw=2)
    ax.plot(minutes, [r["memory"]["uss_total_mib"] for r in rows], label="USS total", ls="--")
    for g in GROUPS:
        ax.plot(minutes, [r["memory"]["rss_mib"][g] for r in rows], label=f"RSS {g}", lw=1)
    ax.axvline(warmup_s / 60, color="grey", ls=":", label="end of warm-up")
    ax.set_xlabel("minutes")
    ax.set_ylabel("MiB")
    ax.set_title("Soak: PPO+ASOR lava world, memory per iteration")
    ax.legend(fontsize=8, loc="center right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# ------------------------------------------------------------------------------ run
def build_algo(args: argparse.Namespace) -> Any:
    from ray.rllib.algorithms.ppo import PPOConfig

    import rllib_asor
    from rllib_asor.algorithms.common.faults import with_fault_tolerance
    from rllib_asor.registry.env_names import register_env

    env = "rllib_asor/LavaWorld-v0"
    register_env(env)  # remote EnvRunners build it through Tune's registry
    config = (
        PPOConfig()
        .environment(env, env_config={"obs_mode": "onehot", "layout": "B"})
        .env_runners(num_env_runners=args.num_env_runners, num_envs_per_env_runner=4,
                     num_cpus_per_env_runner=0.5)
        .training(lr=5e-4, gamma=0.99, lambda_=0.95, entropy_coeff=0.01,
                  train_batch_size=args.train_batch_size, minibatch_size=256,
                  num_epochs=args.num_epochs)
        .rl_module(model_config={"fcnet_hiddens": [64, 64]})
        .debugging(seed=0)
    )
    config = rllib_asor.with_asor(config, mode="asor", lambda_=0.01, rho_value=0.5,
                                  rho_count=0.5, proxy="rnd", reward_form="log")
    return with_fault_tolerance(config).build_algo()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--minutes", type=float, default=30.0, help="wall time to train (default 30)")
    p.add_argument("--warmup-minutes", type=float,
                   help="excluded from the growth figure (default 5; a third of runs < 15 min)")
    p.add_argument("--max-growth", type=float, default=10.0,
                   help="allowed total RSS growth after warm-up, percent (default 10)")
    p.add_argument("--num-env-runners", type=int, default=2)
    p.add_argument("--train-batch-size", type=int, default=2000)
    p.add_argument("--num-epochs", type=int, default=6)
    p.add_argument("--out", default=str(Path(__file__).resolve().parent / "out"))
    args = p.parse_args(argv)
    if args.minutes <= 0:
        p.error(f"--minutes {args.minutes:g} is invalid: allowed a number > 0")
    warmup = args.warmup_minutes
    if warmup is None:
        warmup = 5.0 if args.minutes >= 15 else args.minutes / 3
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    import torch

    cpus = os.cpu_count() or 2
    ray.init(num_cpus=max(cpus, 1 + args.num_env_runners), include_dashboard=False,
             log_to_driver=False, configure_logging=False)
    meta = {
        "command": "python benchmarks/soak.py " + " ".join(argv if argv is not None
                                                            else sys.argv[1:]),
        "machine": platform.platform(), "cpus": cpus, "ray": ray.__version__,
        "torch": torch.__version__, "minutes": args.minutes, "warmup_minutes": warmup,
        "num_env_runners": args.num_env_runners, "train_batch_size": args.train_batch_size,
        "num_epochs": args.num_epochs,
    }
    rows: list[dict] = []
    baseline = memory_snapshot()
    print(f"soak: {args.minutes:g} min, warm-up {warmup:.2f} min; before build: "
          f"{baseline['rss_total_mib']:.0f} MiB RSS", flush=True)
    t_build = time.monotonic()
    algo = build_algo(args)
    meta["build_s"] = round(time.monotonic() - t_build, 1)
    t0 = time.monotonic()  # the clock (and the warm-up) starts with training
    try:
        # At least MIN_ITERATIONS, so that a growth figure exists even for a short check.
        while time.monotonic() - t0 < args.minutes * 60 or len(rows) < MIN_ITERATIONS:
            result = algo.train()
            snap = memory_snapshot()
            ft = result.get("fault_tolerance") or {}
            rows.append({
                "iteration": result["training_iteration"],
                "elapsed_s": round(time.monotonic() - t0, 1),
                "time_this_iter_s": result.get("time_this_iter_s", 0.0),
                "num_env_steps_sampled_lifetime": result.get("num_env_steps_sampled_lifetime"),
                "episode_return_mean": (result.get("env_runners") or {}).get(
                    "episode_return_mean"),
                "asor_disc_loss": (result.get("asor") or {}).get("disc_loss"),
                "num_healthy_workers": ft.get("num_healthy_workers"),
                "num_remote_worker_restarts": ft.get("num_remote_worker_restarts"),
                "memory": snap,
            })
            r = rows[-1]
            print(f"iter {r['iteration']:4d}  {r['elapsed_s'] / 60:5.1f} min  "
                  f"steps {r['num_env_steps_sampled_lifetime']:.0f}  "
                  f"RSS {snap['rss_total_mib']:.0f} MiB (driver {snap['rss_mib']['driver']:.0f}, "
                  f"runners {snap['rss_mib']['env_runners']:.0f})  "
                  f"USS {snap['uss_total_mib']:.0f} MiB", flush=True)
    finally:
        algo.stop()
        ray.shutdown()
    meta["minutes_run"] = (time.monotonic() - t0) / 60
    summary = summarize(rows, warmup * 60, args.max_growth)
    (out / "soak.json").write_text(json.dumps(
        {"meta": meta, "baseline": baseline, "summary": summary, "iterations": rows},
        indent=1))
    write_markdown(out / "soak.md", meta, rows, summary)
    if rows:
        write_plot(out / "soak.png", rows, warmup * 60)
    t = summary["rss_total"]
    print(f"soak: total RSS growth after warm-up {t['percent']}% ({t['start']} -> {t['end']} "
          f"MiB), limit {args.max_growth:g}%: {verdict(summary)}; "
          f"wrote {out / 'soak.md'}", flush=True)
    return 0 if summary["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
