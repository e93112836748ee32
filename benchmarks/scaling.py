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
    python -m benchmarks.scaling --device cuda --parts learner --runners 14 --minibatch 2048 \
        --torch-compile reduce-overhead --compile-backend cudagraphs

`--torch-compile MODE` compiles each Learner's whole update (RLlib's `torch_compile_learner`,
`complete_update`; every part that builds one); the Learner part then reports its untimed
first pass (`learner_warmup_s`: the compile and CUDA graph capture) beside the rate.

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

ALGOS = ("ppo", "asor", "ppo_overlap", "asor_overlap")
PARTS = ("learner", "sample", "e2e", "tune", "split", "sync")
LABELS = {
    "ppo": "PPO",
    "asor": "PPO+ASOR",
    "ppo_overlap": "PPO overlapped",
    "asor_overlap": "PPO+ASOR overlapped",
}
COMPILE_MODES = ("off", "default", "reduce-overhead", "max-autotune")
"""`--torch-compile`: off, or the torch.compile mode of the Learner's compiled update
("reduce-overhead": CUDA graphs on a GPU, the per-minibatch launch cost a GPU Learner pays)."""
COMPILE_BACKENDS = ("inductor", "cudagraphs", "aot_eager")
"""`--compile-backend`: inductor (generated kernels; needs a C compiler, and Triton on a GPU),
cudagraphs (CUDA graphs of the eager kernels, no compiler), aot_eager (eager kernels, for
checking the compiled path on a CPU)."""
OVERLAP = "_overlap"
"""An algorithm name's suffix for `OverlappedPPO` (the runners sample batch k+1 while the
Learner trains on batch k, its lag corrected: rllib_asor/algorithms/ppo/overlap.py)."""


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
    p.add_argument("--algos", default="ppo,asor", help="comma list of " + ", ".join(ALGOS))
    p.add_argument("--parts", default=",".join(PARTS), help="comma list of " + ",".join(PARTS))
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
        "--torch-compile",
        default="off",
        help="compile the Learner's whole update (RLlib's torch_compile_learner, "
        "complete_update) in this torch.compile mode: " + ", ".join(COMPILE_MODES),
    )
    p.add_argument(
        "--compile-backend",
        default="inductor",
        help="its dynamo backend: "
        + ", ".join(COMPILE_BACKENDS)
        + " (cudagraphs: CUDA only; the mode is inductor's, the others ignore it)",
    )
    p.add_argument(
        "--drop-bootstrap-rows",
        action="store_true",
        help="PPO without its masked bootstrap rows (rllib_asor.algorithms.ppo.lean)",
    )
    p.add_argument(
        "--sync-runners", type=int, default=8, help="idle runners of the sync part (1 env each)"
    )
    p.add_argument("--sync-reps", type=int, default=10, help="timed syncs per variant")
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
    if args.torch_compile not in COMPILE_MODES:
        raise ValueError(
            f"--torch-compile {args.torch_compile!r} is invalid: allowed "
            + ", ".join(COMPILE_MODES)
        )
    if args.compile_backend not in COMPILE_BACKENDS:
        raise ValueError(
            f"--compile-backend {args.compile_backend!r} is invalid: allowed "
            + ", ".join(COMPILE_BACKENDS)
        )
    if args.compile_backend == "cudagraphs" and args.device != "cuda":
        raise ValueError("--compile-backend cudagraphs is invalid here: allowed with --device cuda")
    for key in (
        "envs_per_runner",
        "rows_per_runner",
        "minibatch",
        "epochs",
        "rounds",
        "sync_runners",
        "sync_reps",
    ):
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
    tuned_examples/race/ppo(-asor).yaml but with `runners` runners and the batch they make;
    `"ppo_overlap"` / `"asor_overlap"` the same with overlapped sampling."""
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
    if getattr(args, "torch_compile", "off") != "off":
        config = config.framework(
            torch_compile_learner=True,
            torch_compile_learner_what_to_compile="complete_update",
            torch_compile_learner_dynamo_backend=args.compile_backend,
            # a mode is inductor's; torch hands other backends no mode
            torch_compile_learner_dynamo_mode=(
                args.torch_compile if args.compile_backend == "inductor" else None
            ),
        )
    if getattr(args, "drop_bootstrap_rows", False):
        from rllib_asor.algorithms.ppo.lean import drop_bootstrap_rows

        config = drop_bootstrap_rows(config)
    if algo.endswith(OVERLAP):
        from rllib_asor.algorithms.ppo.overlap import overlap_sampling

        config = overlap_sampling(config)
    if algo.removesuffix(OVERLAP) == "asor":
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
    passes, started, warmup_s = 1 + args.learner_passes, time.perf_counter(), 0.0
    for p in range(passes):
        if p == 1:
            warmup_s = time.perf_counter() - started
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
        # The untimed first pass: with --torch-compile, mostly compiling (and CUDA graph capture)
        "warmup_s": warmup_s,
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

        # the split builds PPO and PPO+ASOR side by side: a CPU for each of their runners
        cpus = max(
            os.cpu_count() or 1,
            2 * max(args.runner_counts) + 1,
            args.trials + 1,
            args.sync_runners + 1 if "sync" in args.part_list else 0,
        )
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

        def sample(runner: Any) -> tuple[int, float]:
            t = time.perf_counter()
            n = sum(len(e) for e in runner.sample(num_timesteps=rows))
            return n, time.perf_counter() - t

        group.foreach_env_runner(sample, local_env_runner=False)  # warm-up
        t0 = time.perf_counter()
        done, spread = 0, []
        for _ in range(args.iters):
            t = time.perf_counter()
            calls = group.foreach_env_runner(sample, local_env_runner=False)
            wall = time.perf_counter() - t
            done += sum(n for n, _ in calls)
            secs = [s for _, s in calls]
            spread.append((statistics.median(secs), max(secs), wall))
        out["sample"] = done / (time.perf_counter() - t0)
        # The runners' own `sample()` per call: the median runner, the slowest one (all wait
        # for it in a synchronous loop) and the driver's whole call (episodes stay on the
        # runners here: what is left over the slowest is the call itself).
        medians, slowest, calls_s = zip(*spread, strict=True)
        out["sample_runner_median_s"] = statistics.median(medians)
        out["sample_runner_max_s"] = statistics.median(slowest)
        out["sample_call_s"] = statistics.median(calls_s)
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

    base = race_config(algo.replace("asor", "ppo"), args, 1)
    if args.device == "cuda":  # the trials share the one GPU
        base = base.learners(num_gpus_per_learner=1 / args.trials)
    space = base.to_dict() | {"seed": tune.grid_search(list(range(args.trials)))}
    if algo.removesuffix(OVERLAP) == "asor":
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


# ---------------------------------------------------------------------------- the split
SPLIT_ROWS = (
    # (key, label, depth): depth 1 rows add up to the iteration's wall time, depth 2 rows to
    # the depth 1 row above them, depth 3 rows to the depth 2 row above them
    ("sampling", "sampling (driver's `timers/env_runner_sampling_timer`)", 1),
    ("runner_sample", "the runner's own `sample()` (`env_runners/sample`)", 2),
    ("driver_wait", "the driver's wait beyond it: episodes' transfer, runner metrics", 2),
    ("learner_update", "Learner update (`timers/learner_update_timer`)", 1),
    ("asor_piece", "Learner connector: ASOR's piece (`asor_reward_connector`)", 2),
    ("asor_batch", "features, V(s) of the batch (`_asor_batch`, our timer)", 3),
    ("asor_rank", "archive, ranking, bonus (`AsorTrainer.rank`, our timer)", 3),
    ("asor_learn", "disc and proxy training (`AsorTrainer.learn`, our timer)", 3),
    ("asor_rest", "rewards written, metrics logged", 3),
    ("gae", "Learner connector: GAE", 2),
    ("connector_rest", "Learner connector: the rest (episodes → batch, to torch)", 2),
    ("update", "update: the minibatches (policy, critic)", 2),
    ("learner_reduce", "the Learner's metrics reduce (our timer)", 2),
    ("update_other", "LearnerGroup around it, results aggregated", 2),
    ("weight_sync", "weight sync to the runners (`timers/synch_weights`)", 1),
    ("step_other", "rest of `training_step`", 1),
    ("compile", "metrics compile (`training_iteration` − `training_step`)", 1),
    ("env_sync", "env-runner connector states (`timers/synch_env_connectors`)", 1),
    ("results", "results, callbacks (`train()` − `training_iteration`)", 1),
    ("wall", "iteration, wall clock (`algo.train()`)", 0),
    ("learner_cpu", "the Learner's `update()`, CPU time of the driver (our timer)", 0),
)

_OWN: dict[str, float] = {}
"""Our timers of this process's Learners (the Learner is in the driver), summed per
iteration: read and reset around each `algo.train()`."""


def _own_timer(name: str, fn: Any) -> Any:
    """`fn` wrapped to add its wall time to `_OWN[name]` (after a CUDA sync where torch uses
    CUDA, so GPU work is counted where it is issued)."""
    import functools

    import torch

    def sync() -> None:
        if torch.cuda.is_available() and torch.cuda.is_initialized():
            torch.cuda.synchronize()

    @functools.wraps(fn)
    def timed(*a: Any, **kw: Any) -> Any:
        sync()
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            return fn(*a, **kw)
        finally:
            sync()
            _OWN[name] = _OWN.get(name, 0.0) + time.perf_counter() - t0
            _OWN[name + "_cpu"] = _OWN.get(name + "_cpu", 0.0) + time.process_time() - c0

    timed.__wrapped_by_scaling__ = True  # type: ignore[attr-defined]
    return timed


def install_own_timers() -> None:
    """Our timers inside ASOR's Learner-connector piece (idempotent; this process only)."""
    from rllib_asor.asor.trainer import AsorTrainer
    from rllib_asor.rllib.connector import AsorRewardConnector

    if not getattr(AsorTrainer.rank, "__wrapped_by_scaling__", False):
        AsorTrainer.rank = _own_timer("asor_rank", AsorTrainer.rank)
        AsorTrainer.learn = _own_timer("asor_learn", AsorTrainer.learn)
        cls = AsorRewardConnector
        cls._asor_batch = _own_timer("asor_batch", cls._asor_batch)


def split_config(algo: str, args: argparse.Namespace, runners: int) -> Any:
    """`race_config` reporting RLlib's timers per iteration (`benchmarks.iteration_stats`)."""
    from benchmarks.iteration_stats import ITERATION_STATS

    return race_config(algo, args, runners).reporting(custom_stats_cls_lookup=ITERATION_STATS)


def _flat(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out |= _flat(v, f"{prefix}{k}/")
        else:
            out[f"{prefix}{k}"] = v
    return out


def split_parts(result: dict[str, Any], wall: float, own: dict[str, float]) -> dict[str, float]:
    """One iteration's parts (seconds, keys of `SPLIT_ROWS`) from its result row (RLlib's
    timers, per iteration), the driver's wall time around `train()` and our timers."""
    r = _flat(result)

    def g(key: str) -> float:
        v = r.get(key)
        try:
            v = float(v)
        except (TypeError, ValueError):
            return 0.0
        return 0.0 if v != v else v  # NaN: not logged this iteration

    lc = "learners/__all_modules__/learner_connector/"
    cn = lc + "timers/connectors/"
    p = {
        "wall": wall,
        "sampling": g("timers/env_runner_sampling_timer"),
        "runner_sample": g("env_runners/sample"),
        "learner_update": g("timers/learner_update_timer"),
        "asor_piece": g(cn + "asor_reward_connector"),
        "asor_batch": own.get("asor_batch", 0.0),
        "asor_rank": own.get("asor_rank", 0.0),
        "asor_learn": own.get("asor_learn", 0.0),
        "gae": g(cn + "shared_values_gae") + g(cn + "general_advantage_estimation"),
        "learner_reduce": own.get("learner_reduce", 0.0),
        "weight_sync": g("timers/synch_weights"),
        "learner_cpu": own.get("learner_update_call_cpu", 0.0),
        "env_sync": g("timers/synch_env_connectors"),
    }
    pipeline = g(lc + "connector_pipeline_timer")
    p["driver_wait"] = p["sampling"] - p["runner_sample"]
    p["asor_rest"] = p["asor_piece"] - p["asor_batch"] - p["asor_rank"] - p["asor_learn"]
    p["connector_rest"] = pipeline - p["asor_piece"] - p["gae"]
    p["update"] = own.get("learner_update_call", 0.0) - pipeline - p["learner_reduce"]
    p["update_other"] = p["learner_update"] - own.get("learner_update_call", 0.0)
    step, it = g("timers/training_step"), g("timers/training_iteration")
    p["step_other"] = step - p["sampling"] - p["learner_update"] - p["weight_sync"]
    p["compile"] = it - step
    p["results"] = wall - it - p["env_sync"]
    return p


def measure_split(runners: int, args: argparse.Namespace) -> dict[str, Any]:
    """PPO and PPO+ASOR built side by side (each with `runners` runners), their iterations
    interleaved; per iteration the parts of `SPLIT_ROWS` and the env steps sampled."""
    import torch
    from ray.rllib.utils.metrics import ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME

    torch.set_num_threads(args.learner_threads)
    install_own_timers()
    algos = {a: split_config(a, args, runners).build_algo() for a in args.algo_list}
    for algorithm in algos.values():  # our timers around the (local) Learner's calls
        learner = algorithm.learner_group._learner
        if learner is not None:
            learner.update = _own_timer("learner_update_call", learner.update)
            learner.metrics.reduce = _own_timer("learner_reduce", learner.metrics.reduce)
    iters: dict[str, list[dict[str, float]]] = {a: [] for a in algos}
    last: dict[str, int] = {}
    try:
        for i in range(args.warmup + args.iters):
            for a, algorithm in algos.items():
                _OWN.clear()
                t0 = time.perf_counter()
                res = algorithm.train()
                wall = time.perf_counter() - t0
                steps = int(res[ENV_RUNNER_RESULTS][NUM_ENV_STEPS_SAMPLED_LIFETIME])
                if i >= args.warmup:
                    parts = split_parts(res, wall, dict(_OWN))
                    parts["env_steps"] = steps - last[a]
                    iters[a].append(parts)
                last[a] = steps
    finally:
        for algorithm in algos.values():
            algorithm.stop()
    return {"runners": runners, "iterations": iters}


def split_table(split: dict[str, Any]) -> str:
    """Median ms per iteration of every part, PPO beside PPO+ASOR, and end to end."""
    iters = split["iterations"]
    algos = [a for a in ALGOS if a in iters]
    med = {
        a: {k: statistics.median(it[k] for it in iters[a]) for k, *_ in SPLIT_ROWS} for a in algos
    }
    head = "| part (ms per iteration, median) | " + " | ".join(LABELS[a] for a in algos)
    both = "ppo" in algos and "asor" in algos
    lines = [
        head + (" | PPO+ASOR − PPO | Δ ÷ PPO's iteration |" if both else " |"),
        "|---" * (len(algos) + 1 + 2 * both) + "|",
    ]
    for key, label, depth in SPLIT_ROWS:
        name = ("&nbsp;&nbsp;" * max(0, depth - 1)) + (f"**{label}**" if depth <= 1 else label)
        cells = [f"{1000 * med[a][key]:,.1f}" for a in algos]
        if both:
            d = med["asor"][key] - med["ppo"][key]
            cells += [f"{1000 * d:+,.1f}", f"{100 * d / med['ppo']['wall']:+.1f} %"]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    rates = {
        a: sum(it["env_steps"] for it in iters[a]) / sum(it["wall"] for it in iters[a])
        for a in algos
    }
    lines.append(
        "| **end to end, env steps/s** (steps ÷ wall, all timed iterations) | "
        + " | ".join(f"{rates[a]:,.0f}" for a in algos)
        + (f" | ratio {rates['asor'] / rates['ppo']:.3f} | |" if both else " |")
    )
    if both:
        pairs = [p["wall"] / q["wall"] for p, q in zip(iters["ppo"], iters["asor"], strict=False)]
        lines.append(
            f"| PPO ÷ PPO+ASOR iteration time, per interleaved pair | "
            f"{', '.join(f'{x:.2f}' for x in pairs)} | | | |"
        )
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------- weight sync
def measure_sync(args: argparse.Namespace) -> dict[str, Any]:
    """PPO's weight sync after an update, alone, for PPO+ASOR with `--sync-runners` idle
    runners (1 env each): the bytes of the inference-only state per module, and ms until every
    runner has applied it (the sync as PPO's `training_step` calls it: every module the
    update reported, ASOR's learner-only ones included; then a no-op call on every runner,
    which their actors run after `set_state`), against the policy's modules alone."""
    import pickle

    from ray.rllib.core import COMPONENT_LEARNER, COMPONENT_RL_MODULE, DEFAULT_MODULE_ID

    ns = argparse.Namespace(**{**vars(args), "envs_per_runner": 1})
    algorithm = race_config("asor", ns, args.sync_runners).build_algo()
    group, lg = algorithm.env_runner_group, algorithm.learner_group
    try:
        module_ids = sorted(lg._learner.module.keys()) if lg._learner is not None else []
        state = lg.get_state(
            components=[f"{COMPONENT_LEARNER}/{COMPONENT_RL_MODULE}/{m}" for m in module_ids],
            inference_only=True,
        )[COMPONENT_LEARNER][COMPONENT_RL_MODULE]
        sizes = {m: len(pickle.dumps(state.get(m, {}))) for m in module_ids}
        # a single-agent runner holds the policy's RLModule itself (no MultiRLModule)
        on_runners = group.foreach_env_runner(
            lambda r: sorted(r.module.keys()) if hasattr(r.module, "keys") else [None],
            local_env_runner=False,
        )[0]
        on_runners = [DEFAULT_MODULE_ID if m is None else m for m in on_runners]
        policies = [m for m in module_ids if m in on_runners]
        out: dict[str, Any] = {
            "runners": args.sync_runners,
            "bytes": sizes,
            "runner_modules": on_runners,
        }
        variants = {"as_ppo_calls_it": module_ids, "policy_only": policies}
        times: dict[str, list[float]] = {name: [] for name in variants}
        for i in range(1 + args.sync_reps):  # the variants interleaved; the first round dropped
            for name, mods in variants.items():
                t0 = time.perf_counter()
                group.sync_weights(
                    from_worker_or_learner_group=lg, policies=set(mods), inference_only=True
                )
                group.foreach_env_runner(lambda r: 0, local_env_runner=False)
                if i:
                    times[name].append(time.perf_counter() - t0)
        for name, ts in times.items():
            out[name + "_ms"] = 1000 * statistics.median(ts)
        return out
    finally:
        algorithm.stop()


def sync_table(res: dict[str, Any]) -> str:
    mb = {m: b / 1e6 for m, b in res["bytes"].items()}
    return (
        f"weight sync to {res['runners']} runners (PPO+ASOR; median of the repetitions): as "
        f"PPO calls it (modules {', '.join(sorted(mb))}) {res['as_ppo_calls_it_ms']:.1f} ms; the "
        f"runners' modules only ({', '.join(res['runner_modules'])}) "
        f"{res['policy_only_ms']:.1f} ms; inference-only state per module: "
        + ", ".join(f"{m} {v:.2f} MB" for m, v in mb.items())
        + "\n"
    )


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
                        "learner_warmup_s": res["warmup_s"],
                        "learner_device": res["learner_device"],
                    }
                )
                save()
                print(
                    f"Learner alone {LABELS[algo]} r{n}: {res['env_steps_per_s']:.0f} env steps/s "
                    f"({res['env_steps_per_cpu_s']:.0f} per CPU second) on {res['learner_device']}",
                    flush=True,
                )
    ray_parts = [p for p in args.part_list if p in ("sample", "e2e", "tune", "split", "sync")]
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
                parts = [p for p in ray_parts if p in ("sample", "e2e")]
                if parts:
                    row.update(measure_algo(algo, n, args, parts))
                    save()
                    spread = (
                        f" (per call: the median runner's sample() {row['sample_runner_median_s']:.3f} s,"
                        f" the slowest {row['sample_runner_max_s']:.3f} s, the call {row['sample_call_s']:.3f} s)"
                        if "sample" in parts
                        else ""
                    )
                    print(
                        f"{LABELS[algo]} r{n}: "
                        + ", ".join(f"{p} {row[p]:.0f}" for p in parts)
                        + spread,
                        flush=True,
                    )
            if "split" in ray_parts:
                results["split"] = []
                for n in args.runner_counts:
                    split = measure_split(n, args)
                    results["split"].append(split)
                    save()
                    print(
                        f"\nsplit, {n} runner(s) per algorithm:\n" + split_table(split), flush=True
                    )
            if "sync" in ray_parts:
                results["sync"] = measure_sync(args)
                save()
                print(sync_table(results["sync"]), flush=True)
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
            import ray

            ray.shutdown()  # the Ray it started: a later run in this process starts its own
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
        if "sync" in results:
            print(sync_table(results["sync"]))
        for split in results.get("split", []):
            print(f"split, {split['runners']} runner(s) per algorithm:\n" + split_table(split))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
