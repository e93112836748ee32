"""Race PPO and PPO+ASOR: how throughput grows with env runners, and what the Learner alone does.

For each algorithm (`ppo`, `asor`: race_net, the race env, 8 envs per runner, 1,024 rows per
runner per iteration, minibatch 256, 4 epochs) and each runner count it measures:

- `learner`: the Learner alone, built in-process with `config.build_learner()` (no Ray), fed
  recorded race episodes (sampled once in-process by `SingleAgentEnvRunner`s, deep-copied per
  update): env steps/s through `learner.update(...)`. A batch for N runners is N recorded
  1,024-step batches (runner k's batch b is recorded batch (b + k) mod B, its episode ids made
  distinct). One pass over the recorded batches is dropped as warm-up (ASOR's archive fills
  at its end), then `--learner-passes` passes are timed: by the wall clock, and per second of
  the process's CPU time (steadier on a shared machine; meaningless for a GPU Learner).
- `sample`: the env runners alone (remote, one CPU each), each sampling 1,024 env steps at
  once; env steps/s of all of them together.
- `e2e`: `algo.train()` end to end (sampling, Learner, weight sync), after `--warmup`
  iterations.
- `tune`: `--trials` seeds at once under Tune (each trial 1 runner, the Learner in the
  trial): the sum over trials of env steps/s after each trial's first iteration.

`--device cuda` puts the Learner on the GPU (`num_gpus_per_learner=1`). The parts that need
Ray (`sample`, `e2e`, `tune`) are skipped with one line when Ray cannot start; `learner` never
needs it. `--trees A B` measures only the Learner part, in a fresh process per tree (each
importing `rllib_asor` from its tree, PYTHONPATH) on the same recorded episodes, in
interleaved rounds: a fair before/after ratio on a shared machine.

    python -m benchmarks.scaling --quick                            # 1 and 2 runners, CPU
    python -m benchmarks.scaling --device cuda --runners 1,2,4,8,14
    python -m benchmarks.scaling --parts learner --trees /tmp/before . --rounds 3

Writes OUT/scaling.json (every number, the settings, the machine) and prints one table.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import pickle
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ALGOS = ("ppo", "asor")
PARTS = ("learner", "sample", "e2e", "tune")
LABELS = {"ppo": "PPO", "asor": "PPO+ASOR"}


# ---------------------------------------------------------------------------- arguments
def parse_runners(text: str, cpus: int | None = None) -> list[int]:
    """`--runners` "1,2,4" → [1, 2, 4], keeping the counts this machine has a CPU for (one per
    runner; the Learner shares them). ValueError (one line) for anything else."""
    try:
        wanted = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        wanted = []
    if not wanted or any(n < 1 for n in wanted):
        raise ValueError(f"--runners {text!r} is invalid: allowed positive integers, e.g. 1,2,4")
    cpus = (os.cpu_count() or 1) if cpus is None else cpus
    kept = [n for n in wanted if n <= max(1, cpus)]
    return kept or [1]


def parse_list(text: str, allowed: tuple[str, ...], flag: str) -> list[str]:
    """A comma list of names from `allowed`; ValueError naming the flag, the value, the choices."""
    items = [x.strip() for x in text.split(",") if x.strip()]
    if not items or any(x not in allowed for x in items):
        raise ValueError(
            f"{flag} {text!r} is invalid: allowed a comma list of {', '.join(allowed)}"
        )
    return items


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--device", default="cpu", help="the Learner's device: cpu or cuda")
    p.add_argument("--runners", default="1,2,4,8,14", help="env-runner counts (comma list)")
    p.add_argument("--algos", default="ppo,asor", help="comma list of ppo, asor")
    p.add_argument(
        "--parts", default="learner,sample,e2e,tune", help="comma list of " + ",".join(PARTS)
    )
    p.add_argument("--quick", action="store_true", help="fewer batches and iterations (minutes)")
    p.add_argument("--envs-per-runner", type=int, default=8)
    p.add_argument(
        "--rows-per-runner", type=int, default=1024, help="env steps per runner per iteration"
    )
    p.add_argument("--minibatch", type=int, default=256)
    p.add_argument("--epochs", type=int, default=4)
    p.add_argument(
        "--record-batches",
        type=int,
        default=None,
        help="recorded 1-runner batches (default 6, quick 3)",
    )
    p.add_argument(
        "--learner-passes", type=int, default=None, help="timed passes (default 2, quick 1)"
    )
    p.add_argument(
        "--learner-threads",
        type=int,
        default=None,
        help="torch threads of the Learner (default: OMP_NUM_THREADS or 1)",
    )
    p.add_argument(
        "--iters", type=int, default=None, help="timed e2e iterations (default 5, quick 2)"
    )
    p.add_argument("--warmup", type=int, default=1, help="untimed e2e iterations")
    p.add_argument(
        "--trials", type=int, default=None, help="Tune trials at once (default cpus // 2, quick 2)"
    )
    p.add_argument(
        "--trees", nargs="+", default=None, help="source trees: Learner part only, per tree"
    )
    p.add_argument("--rounds", type=int, default=1, help="interleaved rounds over --trees")
    p.add_argument("--model-config", type=json.loads, default={}, help="race_net settings (JSON)")
    p.add_argument(
        "--drop-bootstrap-rows",
        action="store_true",
        help="PPO without its masked bootstrap rows (rllib_asor.algorithms.ppo.lean)",
    )
    p.add_argument("--out", default="benchmarks/out/scaling")
    p.add_argument("--learner-job", default=None, help=argparse.SUPPRESS)  # internal: one tree
    return p


def settle(args: argparse.Namespace) -> argparse.Namespace:
    """Validate and fill the defaults that depend on `--quick`; ValueError with one line."""
    if args.device not in ("cpu", "cuda"):
        raise ValueError(f"--device {args.device!r} is invalid: allowed cpu or cuda")
    args.runner_counts = parse_runners(args.runners)
    args.algo_list = parse_list(args.algos, ALGOS, "--algos")
    args.part_list = parse_list(args.parts, PARTS, "--parts")
    for key in ("envs_per_runner", "rows_per_runner", "minibatch", "epochs", "rounds"):
        if getattr(args, key) < 1:
            raise ValueError(
                f"--{key.replace('_', '-')} {getattr(args, key)} is invalid: allowed ≥ 1"
            )
    q = args.quick
    args.record_batches = args.record_batches or (3 if q else 6)
    args.learner_passes = args.learner_passes or (1 if q else 2)
    args.iters = args.iters or (2 if q else 5)
    args.trials = args.trials or (2 if q else max(2, (os.cpu_count() or 2) // 2))
    threads = args.learner_threads or int(os.environ.get("OMP_NUM_THREADS", "1") or 1)
    args.learner_threads = max(1, threads)
    return args


# ---------------------------------------------------------------------------- configs
def race_config(algo: str, args: argparse.Namespace, runners: int, seed: int = 0) -> Any:
    """Race PPO (`algo="ppo"`) or PPO+ASOR's robust default (`"asor"`), as
    tuned_examples/race/ppo(-asor).yaml but with `runners` runners and the batch they make."""
    import rllib_asor
    from rllib_asor.race.config import RACE_ASOR_OBS_KEYS, race_ppo_config

    config = (
        race_ppo_config(
            num_racers=1, map_id="random", max_episode_steps=1000, model_config=args.model_config
        )
        .env_runners(
            num_env_runners=runners,
            num_envs_per_env_runner=args.envs_per_runner,
            num_cpus_per_env_runner=1,
        )
        .training(
            train_batch_size=args.rows_per_runner * runners,
            # RLlib refuses a minibatch larger than the batch (1 runner at --minibatch 2048)
            minibatch_size=min(args.minibatch, args.rows_per_runner * runners),
            num_epochs=args.epochs,
            lr=[[0, 0.001], [2_000_000, 0.0003]],
            gamma=0.99,
            lambda_=0.95,
            entropy_coeff=0.003,
        )
        .debugging(seed=seed)
    )
    if args.device == "cuda":
        config = config.learners(num_gpus_per_learner=1)
    if getattr(args, "drop_bootstrap_rows", False):
        from rllib_asor.algorithms.ppo.lean import drop_bootstrap_rows

        config = drop_bootstrap_rows(config)
    if algo == "asor":
        config = rllib_asor.with_asor(config, mode="asor", obs_keys=list(RACE_ASOR_OBS_KEYS))
    return config


# ---------------------------------------------------------------------------- Learner alone
def record_episodes(args: argparse.Namespace) -> list[list[Any]]:
    """`record_batches` batches of `rows_per_runner` env steps from one in-process env runner
    (PPO's exploration policy at its initial weights; no Ray)."""
    from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner

    config = race_config("ppo", argparse.Namespace(**{**vars(args), "device": "cpu"}), 0)
    runner = SingleAgentEnvRunner(config=config)
    batches = []
    for _ in range(args.record_batches):
        episodes, done = [], 0
        while done < args.rows_per_runner:
            got = runner.sample(num_timesteps=args.rows_per_runner - done, random_actions=False)
            episodes += got
            done += sum(len(e) for e in got)
        batches.append(episodes)
    runner.stop()
    return batches


def runner_batch(recorded: list[list[Any]], b: int, runners: int) -> list[Any]:
    """The batch of update `b` with `runners` runners: runner k brings recorded batch
    (b + k) mod B, deep-copied (the Learner connector extends episodes in place), with episode
    ids made distinct per runner."""
    episodes = []
    for k in range(runners):
        for ep in copy.deepcopy(recorded[(b + k) % len(recorded)]):
            ep.id_ = f"{ep.id_}r{k}"
            episodes.append(ep)
    return episodes


def measure_learner(
    algo: str, runners: int, recorded: list[list[Any]], args: argparse.Namespace
) -> dict[str, Any]:
    """Env steps/s of race batches through `learner.update` (one pass warm-up, then timed)."""
    import torch
    from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

    torch.set_num_threads(args.learner_threads)
    torch.manual_seed(0)
    config = race_config(algo, args, runners)
    learner = _build_learner(config)
    cuda = args.device == "cuda"
    lifetime, times, cpu_times, steps = 0, [], [], []
    passes = 1 + args.learner_passes
    for p in range(passes):
        for b in range(len(recorded)):
            episodes = runner_batch(recorded, b, runners)
            n = sum(len(e) for e in episodes)
            lifetime += n
            t0, c0 = time.perf_counter(), time.process_time()
            learner.update(
                episodes=episodes,
                timesteps={NUM_ENV_STEPS_SAMPLED_LIFETIME: lifetime},
                num_epochs=args.epochs,
                minibatch_size=min(args.minibatch, args.rows_per_runner * runners),
                shuffle_batch_per_epoch=True,
            )
            if cuda:
                torch.cuda.synchronize()
            if p > 0:
                times.append(time.perf_counter() - t0)
                cpu_times.append(time.process_time() - c0)
                steps.append(n)
    device = str(next(learner.module[next(iter(learner.module.keys()))].parameters()).device)
    rows = args.rows_per_runner * runners
    minibatches = -(-args.epochs * rows // min(args.minibatch, rows))
    return {
        "env_steps_per_s": sum(steps) / sum(times),
        # Per second of this process's CPU time: on a CPU Learner with one torch thread, what
        # other jobs on a shared machine change least (they take wall time, not its CPU time).
        "env_steps_per_cpu_s": sum(steps) / sum(cpu_times),
        "update_s_median": statistics.median(times),
        "ms_per_minibatch": 1000 * sum(times) / len(times) / minibatches,
        "updates_timed": len(times),
        "learner_device": device,
    }


def _build_learner(config: Any) -> Any:
    """`config.build_learner()` with the race env's spaces (no env is made)."""
    from ray.rllib.core import DEFAULT_MODULE_ID

    import game_env

    spaces = {DEFAULT_MODULE_ID: (game_env.observation_space(), game_env.action_space())}
    return config.build_learner(spaces=spaces)


def learner_job(job_file: str) -> int:
    """Internal: measure the Learner part with this process's `rllib_asor` (a `--trees` run)."""
    job = pickle.loads(Path(job_file).read_bytes())
    args = job["args"]
    res = measure_learner(job["algo"], job["runners"], job["recorded"], args)
    Path(job_file + ".out").write_text(json.dumps(res))
    return 0


def learner_trees(recorded: list[list[Any]], args: argparse.Namespace) -> list[dict[str, Any]]:
    """The Learner part per source tree, in fresh processes, interleaved over `--rounds`."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            for n in args.runner_counts:
                for algo in args.algo_list:
                    for tree_ in args.trees:
                        tree = Path(tree_).resolve()
                        job = Path(tmp) / "job.pkl"
                        ns = argparse.Namespace(
                            **{k: v for k, v in vars(args).items() if k != "trees"}
                        )
                        job.write_bytes(
                            pickle.dumps(
                                {"args": ns, "algo": algo, "runners": n, "recorded": recorded}
                            )
                        )
                        env = {**os.environ, "PYTHONPATH": str(tree), "PYTHONHASHSEED": "0"}
                        cmd = [sys.executable, os.path.abspath(__file__), "--learner-job", str(job)]
                        proc = subprocess.run(
                            cmd, env=env, capture_output=True, text=True, cwd=tree
                        )
                        if proc.returncode != 0:
                            raise RuntimeError(f"{tree} {algo} r{n}: {proc.stderr[-2000:]}")
                        res = json.loads((Path(str(job) + ".out")).read_text())
                        rows.append(
                            res | {"tree": str(tree), "algo": algo, "runners": n, "round": r}
                        )
                        print(
                            f"round {r} {tree.name} {LABELS[algo]} r{n}: {res['env_steps_per_s']:.0f} env steps/s "
                            f"({res['ms_per_minibatch']:.1f} ms/minibatch)",
                            flush=True,
                        )
    return rows


# ---------------------------------------------------------------------------- with Ray
def start_ray(args: argparse.Namespace) -> str | None:
    """Start a local Ray with a CPU per runner; None, or the one-line reason it cannot start."""
    try:
        import ray

        cpus = max(os.cpu_count() or 1, max(args.runner_counts) + 1, args.trials + 1)
        ray.init(
            address="local",
            num_cpus=cpus,
            include_dashboard=False,
            log_to_driver=False,
            configure_logging=False,
        )
        return None
    except Exception as e:  # noqa: BLE001 - any failure means: skip the Ray parts
        return f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"


def measure_algo(
    algo: str, runners: int, args: argparse.Namespace, parts: list[str]
) -> dict[str, Any]:
    """`sample` and `e2e` for one algorithm and runner count (one Algorithm)."""
    from ray.rllib.utils.metrics import ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME

    out: dict[str, Any] = {}
    algorithm = race_config(algo, args, runners).build_algo()
    group = algorithm.env_runner_group
    rows = args.rows_per_runner
    if "sample" in parts:

        def sample(runner: Any) -> int:
            return sum(len(e) for e in runner.sample(num_timesteps=rows))

        group.foreach_env_runner(sample, local_env_runner=False)  # warm-up
        t0 = time.perf_counter()
        done = 0
        for _ in range(args.iters):
            done += sum(group.foreach_env_runner(sample, local_env_runner=False))
        out["sample"] = done / (time.perf_counter() - t0)
    if "e2e" in parts:
        for _ in range(args.warmup):
            algorithm.train()

        def lifetime(res: dict[str, Any]) -> int:
            return int(res[ENV_RUNNER_RESULTS][NUM_ENV_STEPS_SAMPLED_LIFETIME])

        start = lifetime(algorithm.train())
        t0 = time.perf_counter()
        for _ in range(args.iters):
            res = algorithm.train()
        out["e2e"] = (lifetime(res) - start) / (time.perf_counter() - t0)
    algorithm.stop()
    return out


def measure_tune(algo: str, args: argparse.Namespace) -> float:
    """`--trials` seeds of race PPO(+ASOR) at once under Tune, 1 runner each (on a GPU, each
    Learner gets 1/trials of it): the sum of their env steps/s after their first iteration."""
    from ray import tune

    from rllib_asor.rllib.trainable import asor_trainable

    base = race_config("ppo", args, 1)
    if args.device == "cuda":  # the trials share the one GPU
        base = base.learners(num_gpus_per_learner=1 / args.trials)
    space = base.to_dict() | {"seed": tune.grid_search(list(range(args.trials)))}
    if algo == "asor":
        from rllib_asor.race.config import RACE_ASOR_OBS_KEYS

        space["asor"] = {"mode": "asor", "obs_keys": list(RACE_ASOR_OBS_KEYS)}
    with tempfile.TemporaryDirectory() as tmp:
        results = tune.Tuner(
            asor_trainable("PPO"),
            param_space=space,
            run_config=tune.RunConfig(
                storage_path=tmp, stop={"training_iteration": 1 + args.iters}, verbose=0
            ),
        ).fit()
        total = 0.0
        for result in results:
            if result.error:
                raise RuntimeError(f"Tune trial failed: {result.error}")
            df = result.metrics_dataframe
            steps = df["env_runners/num_env_steps_sampled_lifetime"]
            wall = df["time_total_s"]
            total += (steps.iloc[-1] - steps.iloc[0]) / (wall.iloc[-1] - wall.iloc[0])
    return total


# ---------------------------------------------------------------------------- table
def table(results: dict[str, Any]) -> str:
    """One markdown table: a row per algorithm and runner count."""
    lines = [
        "| algorithm | env runners | end to end (env steps/s) | sampling only | Learner alone "
        "| Learner alone per CPU second | ms per minibatch | Tune trials at once (sum) |",
        "|---|---|---|---|---|---|---|---|",
    ]

    def cell(x: Any) -> str:
        return "—" if x is None else (x if isinstance(x, str) else f"{x:,.0f}")

    for row in results["rows"]:
        ms = row.get("ms_per_minibatch")
        lines.append(
            f"| {LABELS[row['algo']]} | {row['runners']} | {cell(row.get('e2e'))} "
            f"| {cell(row.get('sample'))} | {cell(row.get('learner'))} "
            f"| {cell(row.get('learner_per_cpu_s'))} | {'—' if ms is None else f'{ms:.1f}'} | {cell(row.get('tune'))} |"
        )
    return "\n".join(lines) + "\n"


def machine() -> str:
    """CPU count and GPU name, for the record."""
    text = f"{os.cpu_count()} CPUs"
    try:
        import torch

        if torch.cuda.is_available():
            text += f", {torch.cuda.get_device_name(0)}"
    except Exception:  # noqa: BLE001
        pass
    return text


def check_device(device: str) -> None:
    """ValueError (one line) when `--device cuda` is asked for and torch sees no CUDA device."""
    import torch

    if device == "cuda" and not torch.cuda.is_available():
        raise ValueError("--device 'cuda' is invalid here: torch sees no CUDA device; allowed cpu")


def run(args: argparse.Namespace, out: Path) -> dict[str, Any]:
    """Every part asked for; OUT/scaling.json is rewritten after each measurement, so a run
    stopped by a time limit leaves what it measured (`"finished": false`)."""
    os.environ.setdefault("OMP_NUM_THREADS", str(args.learner_threads))
    rows = {(a, n): {"algo": a, "runners": n} for a in args.algo_list for n in args.runner_counts}
    results: dict[str, Any] = {
        "machine": machine(),
        "settings": {k: v for k, v in vars(args).items()},
        "notes": [],
    }
    t0 = time.time()
    out.mkdir(parents=True, exist_ok=True)

    def save(finished: bool = False) -> None:
        results.update(rows=list(rows.values()), wall_s=time.time() - t0, finished=finished)
        tmp = out / "scaling.json.tmp"
        tmp.write_text(json.dumps(results, indent=1, default=str))
        os.replace(tmp, out / "scaling.json")

    if "learner" in args.part_list:
        recorded = record_episodes(args)
        print(
            f"recorded {len(recorded)} batches of {args.rows_per_runner} env steps "
            f"({time.time() - t0:.0f} s)",
            flush=True,
        )
        if args.trees:
            results["trees"] = learner_trees(recorded, args)
            for row in results["trees"]:
                print(json.dumps(row), flush=True)
        else:
            for (algo, n), row in rows.items():
                res = measure_learner(algo, n, recorded, args)
                row.update(
                    {
                        "learner": res["env_steps_per_s"],
                        "learner_per_cpu_s": res["env_steps_per_cpu_s"],
                        "ms_per_minibatch": res["ms_per_minibatch"],
                        "learner_device": res["learner_device"],
                    }
                )
                save()
                print(
                    f"Learner alone {LABELS[algo]} r{n}: {res['env_steps_per_s']:.0f} env steps/s "
                    f"({res['env_steps_per_cpu_s']:.0f} per CPU second) on {res['learner_device']}",
                    flush=True,
                )
    ray_parts = [p for p in args.part_list if p in ("sample", "e2e", "tune")]
    if ray_parts and not args.trees:
        why = start_ray(args)
        if why is not None:
            line = f"skipped {', '.join(ray_parts)}: Ray cannot start here ({why})"
            results["notes"].append(line)
            print(line, flush=True)
            save()
        else:
            from rllib_asor.race.config import register_race_envs

            register_race_envs()
            for (algo, n), row in rows.items():
                parts = [p for p in ray_parts if p != "tune"]
                if parts:
                    row.update(measure_algo(algo, n, args, parts))
                    save()
                    print(
                        f"{LABELS[algo]} r{n}: " + ", ".join(f"{p} {row[p]:.0f}" for p in parts),
                        flush=True,
                    )
            if "tune" in ray_parts:
                for algo in args.algo_list:
                    try:
                        rate = measure_tune(algo, args)
                    except Exception as e:  # noqa: BLE001 - reported, the rest of the table stands
                        line = f"Tune part of {LABELS[algo]} failed: {type(e).__name__}: {e}"
                        results["notes"].append(line.splitlines()[0])
                        print(line.splitlines()[0], flush=True)
                        continue
                    rows[(algo, 1)]["tune"] = f"{rate:,.0f} ({args.trials} trials)"
                    save()
                    print(
                        f"Tune {LABELS[algo]} {args.trials} trials: {rate:.0f} env steps/s",
                        flush=True,
                    )
    save(finished=True)
    return results


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.learner_job:
        return learner_job(args.learner_job)
    try:
        args = settle(args)
        check_device(args.device)
    except ValueError as e:
        print(f"scaling: {e}", file=sys.stderr)
        return 2
    results = run(args, Path(args.out))
    print(
        f"\nmachine: {results['machine']}; Learner on {args.device}, {args.learner_threads} torch thread(s); "
        f"wall {results['wall_s']:.0f} s"
    )
    for note in results["notes"]:
        print(note)
    if "trees" in results:
        by: dict[tuple[str, str, int], list[float]] = {}
        for r in results["trees"]:
            by.setdefault((r["tree"], r["algo"], r["runners"]), []).append(r["env_steps_per_cpu_s"])
        print(
            "| tree | algorithm | env runners | Learner alone env steps per CPU second (median) | per round |"
        )
        print("|---|---|---|---|---|")
        for (tree, algo, n), v in by.items():
            print(
                f"| {tree} | {LABELS[algo]} | {n} | {statistics.median(v):,.0f} | {', '.join(f'{x:.0f}' for x in v)} |"
            )
    else:
        print(table(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
