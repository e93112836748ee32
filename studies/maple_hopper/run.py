"""MAPLE vs MAPLE+ASOR on the mixed-dynamics Hopper data, CQL and MOPO beside.

A resumable runner: one independent job per (dataset, method, seed), each run saved at once to
RUNS/<dataset>-<method>-<seed>.json.gz; a rerun skips finished runs, and a job another process is
running (its lock file names a live pid) is skipped too, so several processes (one per core,
different --datasets / --seeds) can share one folder. An unfinished run is saved after every
iteration (RUNS/<name>.partial/: the algorithm with its model pool and sampler, the curve; ~0.6
GB, not committed) and a rerun continues it from there, so a run that is cut off
loses at most one iteration. The decision rule and the budget are
fixed before any run (studies/maple_hopper/README.md names the commit).

Data: `rllib data collect` Hopper parts of one quality from all three dynamics (`original`,
`body_mass`, `density_10`), mixed, as the paper. Every run trained on one build (`data/`: the
medium and random parts and the manifest of one `make datasets DATASET_STEPS=20000` build);
rebuilding gives other rows on another machine. The build is not in the tree: the README gives
its sha256 fingerprints and the `git archive` command that restores it from history
(`--data` points elsewhere if you want your own build). Methods:
- `maple`: `MapleConfig` (tuned_examples/offline/maple-hopper.yaml's settings);
- `maple_asor_paper`: `with_asor(..., preset="paper", lambda_=0.1)` (the paper's form, SRPO's η);
- `maple_asor`: `with_asor(...)` (the robust default);
- `mopo`: `MopoConfig` (the context off, h 5, λ_u 1);
- `cql`: the project's CQL (tuned_examples/offline/cql-hopper.yaml, fast path) for the same
  number of gradient steps.
MAPLE, both MAPLE+ASOR and MOPO of one (dataset, seed) load the same cached ensemble (trained by
whichever runs first; run the `maple` jobs first, or `--ensembles-only` first, or one process
per dataset). The ensembles are cached in `ensembles/` (keyed by the data's bytes and the
ensemble settings; restored like the data), so the methods of one seed may run at different
times and still share theirs.

Score: the deterministic policy, `--eval-episodes` episodes under each dynamics, D4RL-normalised
against the dataset's own random and expert returns (`rllib_asor.data.scoring.normalized_score`),
averaged over the three dynamics; every `--eval-every` iterations on the way (fewer episodes)
and at the end.

    cd /work/main && OMP_NUM_THREADS=1 nice -n 5 .venv/bin/python \\
        studies/maple_hopper/run.py --datasets medium --seeds 0 1 2
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from studies.lib.run_files import existing, read_run, run_file, run_paths, write_run  # noqa: E402

ENV_ID = "rllib_asor/HopperShift-v0"
DYNAMICS = ("original", "body_mass", "density_10")
METHODS = ("maple", "maple_asor_paper", "maple_asor", "mopo", "cql")
HERE = Path(__file__).resolve().parent


def parts(args: argparse.Namespace, dataset: str) -> list[str]:
    root = Path(args.data).resolve()
    return [str(root / d / dataset) for d in DYNAMICS]


def maple_config(method: str, dataset: str, seed: int, args: argparse.Namespace) -> Any:
    """MAPLE / MAPLE+ASOR / MOPO of one run."""
    import rllib_asor

    cls = rllib_asor.MopoConfig if method == "mopo" else rllib_asor.MapleConfig
    settings = {
        "steps_per_iteration": args.steps_per_iter,
        "rollout_batch_size": args.rollout_batch_size,
        "evaluation_interval": args.eval_every,
        "evaluation_episodes": args.eval_episodes_during,
        "ensemble_cache": args.ensemble_cache,
        "ensemble_max_epochs": args.ensemble_max_epochs,
        "checkpoint_model_pool": True,  # the partial saves resume with the run's own pool
        "ensemble": "tf_maple",  # what this study ran (7 / 5 / 200; the default is now 20 / 14 / 256)
    }
    if method == "mopo":  # what this study ran (MOPO's own hopper-medium setting is h 5, λ 5)
        settings.update(horizon=5, penalty_coef=1.0)
    config = (
        cls()
        .environment(ENV_ID, env_config={"dynamics": "original"})
        .offline_data(input_=parts(args, dataset))
        .maple(**settings)
        .debugging(seed=seed, log_level="ERROR")
    )
    if method == "maple_asor_paper":
        config = rllib_asor.with_asor(config, preset="paper", lambda_=0.1, seed=seed)
    elif method == "maple_asor":
        config = rllib_asor.with_asor(config, seed=seed)
    return config


def cql_config(dataset: str, seed: int, args: argparse.Namespace) -> Any:
    """CQL as tuned_examples/offline/cql-hopper.yaml (fast path), `steps_per_iter` updates per
    iteration."""
    from ray.rllib.algorithms.cql import CQLConfig

    from rllib_asor.algorithms.cql.offline import offline_input
    from rllib_asor.algorithms.sac.fast import fast_off_policy

    config = (
        CQLConfig()
        .environment(ENV_ID, env_config={"dynamics": "original"})
        .env_runners(num_env_runners=0)
        .learners(num_learners=0)
        .training(
            train_batch_size_per_learner=256,
            lr=None,
            actor_lr=1e-4,
            critic_lr=3e-4,
            alpha_lr=1e-4,
            bc_iters=20,
            min_q_weight=5.0,
            gamma=0.99,
            tau=0.005,
        )
        .evaluation(evaluation_interval=None)
        .debugging(seed=seed, log_level="ERROR")
    )
    offline_input(
        config,
        args.data,
        quality=dataset,
        dataset_num_iters_per_learner=args.steps_per_iter,
    )
    return fast_off_policy(config)


def evaluate_run(algo: Any, method: str, args: argparse.Namespace, episodes: int) -> dict:
    from rllib_asor.data.format import read_manifest

    manifest = read_manifest(args.data)
    if method == "cql":
        from rllib_asor.data.scoring import evaluate

        return evaluate(algo, manifest, episodes=episodes, seed=100_000)
    from rllib_asor.algorithms.maple.evaluation import evaluate as maple_evaluate
    from rllib_asor.algorithms.maple.maple import DEFAULT_MODULE_ID

    module = algo.learner_group._learner.module[DEFAULT_MODULE_ID].unwrapped()
    return maple_evaluate(module.nets, manifest, episodes=episodes, seed=100_000)


def data_fingerprint(paths: list[str]) -> str:
    """A hash of the rows of the dataset parts (not of the files' names or metadata): runs are
    only paired when they trained on the same rows (summarise.py checks; the first runs
    trained on earlier builds of the data)."""
    import hashlib

    import pyarrow.parquet as pq

    h = hashlib.sha256()
    for part in paths:
        files = sorted(Path(part).glob("*.parquet"))
        rows = [
            json.dumps(pq.read_table(f).to_pydict(), sort_keys=True, default=str) for f in files
        ]
        for digest in sorted(hashlib.sha256(r.encode()).hexdigest() for r in rows):
            h.update(digest.encode())
    return h.hexdigest()[:16]


def run_one(
    dataset: str,
    method: str,
    seed: int,
    args: argparse.Namespace,
    partial: Path,
    fingerprint: str,
) -> dict[str, Any]:
    """Train one run for `args.iters` iterations, saved to `partial` after each one and
    continued from there when a run was saved; `fingerprint`: `data_fingerprint` of the
    dataset's parts (the runner hashes each dataset once)."""
    import numpy as np

    from studies.lib.common import load_partial, save_partial

    cfg = (
        cql_config(dataset, seed, args)
        if method == "cql"
        else maple_config(method, dataset, seed, args)
    )
    t0 = time.time()
    algo = cfg.build_algo()
    setup_s = time.time() - t0
    curve, done, spent, resumed_at = [], 0, 0.0, []
    if (found := load_partial(partial)) is not None:
        saved, checkpoint = found
        algo.restore_from_path(str(checkpoint))
        curve, done, spent = saved["curve"], saved["iteration"], saved["train_s"]
        resumed_at = [*saved["resumed_at"], done]
        print(f"  {dataset}/{method}/{seed}: resumed after iteration {done}", flush=True)
    last, t1 = {}, time.time() - spent
    try:
        for i in range(done, args.iters):
            last = algo.train()
            ev = last.get("evaluation", {})
            score = float(ev.get("mean/normalized_score", float("nan")))
            if np.isfinite(score):  # iterations without an evaluation report NaN
                curve.append({"iteration": i + 1, "score": score})
            if i + 1 < args.iters:
                state = {
                    "curve": curve,
                    "iteration": i + 1,
                    "resumed_at": resumed_at,
                    "train_s": time.time() - t1,
                }
                save_partial(partial, state, lambda folder: algo.save_to_path(str(folder)))
            print(
                f"  {dataset}/{method}/{seed} iter {i + 1}/{args.iters} "
                f"t={time.time() - t1:.0f}s {curve[-1] if curve else ''}",
                flush=True,
            )
        train_s = time.time() - t1
        final = evaluate_run(algo, method, args, args.eval_episodes)
    finally:
        algo.stop()

    def scalars(d: Any) -> dict[str, float]:
        return {k: float(v) for k, v in (d or {}).items() if np.isscalar(v)}

    return {
        "dataset": dataset,
        "data_fingerprint": fingerprint,
        "method": method,
        "seed": seed,
        "iters": args.iters,
        "gradient_steps": args.iters * args.steps_per_iter,
        "rollout_batch_size": args.rollout_batch_size,
        "ensemble_max_epochs": args.ensemble_max_epochs,
        "eval_episodes": args.eval_episodes,
        "setup_s": setup_s,
        "train_s": train_s,
        "wall_s": setup_s + time.time() - t1,
        "resumed_at": resumed_at,
        "final": final,
        "score": final["mean"]["normalized_score"],
        "curve": curve,
        "maple_last": scalars(last.get("maple")),
        "asor_last": scalars(last.get("asor")),
    }


def runs_on_other_data(runs: Path, dataset: str, seed: int, fingerprint: str) -> list[str]:
    """The finished runs of this (dataset, seed) that trained on other rows: a new run here
    could not pair with them (summarise.py refuses a (dataset, seed) from two data builds)."""
    return [
        path.name
        for path in run_paths(runs, f"{dataset}-*-{seed}")
        if (r := read_run(path))["dataset"] == dataset
        and int(r["seed"]) == seed
        and r.get("data_fingerprint") != fingerprint
    ]


def _locked_by_other(lock: Path) -> bool:
    if not lock.exists():
        return False
    try:
        pid = int(lock.read_text().strip())
        os.kill(pid, 0)
        return pid != os.getpid()
    except (ValueError, ProcessLookupError):
        return False  # stale
    except PermissionError:
        return True


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument(
        "--data", default=str(HERE / "data"), help="task dir (default: the study's data, README.md)"
    )
    p.add_argument("--datasets", nargs="+", default=["medium", "random"])
    p.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    p.add_argument("--iters", type=int, default=20, help="iterations per run (the rule: 20)")
    p.add_argument("--steps-per-iter", type=int, default=1000, help="gradient steps per iteration")
    p.add_argument(
        "--rollout-batch-size", type=int, default=50_000, help="model rollouts per iteration"
    )
    p.add_argument("--eval-every", type=int, default=5, help="iterations between evaluations")
    p.add_argument("--eval-episodes-during", type=int, default=3)
    p.add_argument("--eval-episodes", type=int, default=10, help="final, per dynamics")
    p.add_argument(
        "--ensemble-max-epochs",
        type=int,
        default=100,
        help="cap on ensemble epochs (the port: until 5 epochs without improvement; the "
        "study's budget: 100, studies/maple_hopper/README.md)",
    )
    p.add_argument(
        "--ensemble-cache",
        default=str(HERE / "ensembles"),
        help="trained ensembles, one per (dataset, seed), cached (default: beside this file) "
        "so that the methods of one seed can run at different times and still share it",
    )
    p.add_argument("--runs", default=str(HERE / "runs"))
    p.add_argument(
        "--ensembles-only",
        action="store_true",
        help="only train (or find) the cached ensembles of --datasets x --seeds, then exit: the "
        "methods of one seed can then run in parallel processes on one ensemble",
    )
    args = p.parse_args(argv)

    from rllib_asor.data.format import read_manifest

    if not (Path(args.data) / "manifest.json").exists():
        raise SystemExit(
            f"--data={args.data}: no manifest.json; restore the study's data "
            "(studies/maple_hopper/README.md) or make your own with `make datasets`"
        )
    read_manifest(args.data)  # fails here, naming `make datasets`, when the data is missing
    for d in args.datasets:
        for path in parts(args, d):
            if not Path(path).is_dir():
                raise SystemExit(
                    f"missing dataset part {path}; make the data first: `make datasets`"
                )
    from studies.lib.common import start_local_ray

    start_local_ray(num_cpus=4)  # CQL: Ray Data takes a read task and two OfflinePreLearner actors
    if args.ensembles_only:
        for seed in args.seeds:
            for dataset in args.datasets:
                maple_config("maple", dataset, seed, args).build_algo().stop()
                print(f"ensemble of {dataset} seed {seed} in {args.ensemble_cache}", flush=True)
        return
    runs = Path(args.runs)
    runs.mkdir(parents=True, exist_ok=True)
    prints = {ds: data_fingerprint(parts(args, ds)) for ds in args.datasets}
    for seed in args.seeds:
        for dataset in args.datasets:
            for method in args.methods:
                name = f"{dataset}-{method}-{seed}"
                out, lock = run_file(runs, name), runs / f"{name}.lock"
                if existing(out) or _locked_by_other(lock):
                    continue
                if other := runs_on_other_data(runs, dataset, seed, prints[dataset]):
                    print(
                        f"skip {name}: {', '.join(other)} trained on another build of the "
                        f"data, so this run could not pair with them; use another seed",
                        flush=True,
                    )
                    continue
                lock.write_text(str(os.getpid()))
                try:
                    print(f"run {name}", flush=True)
                    partial = runs / f"{name}.partial"
                    res = run_one(dataset, method, seed, args, partial, prints[dataset])
                    write_run(out, res)
                    shutil.rmtree(partial, ignore_errors=True)
                    print(
                        f"  {name}: score {res['score']:.1f} wall {res['wall_s']:.0f}s", flush=True
                    )
                finally:
                    lock.unlink(missing_ok=True)


if __name__ == "__main__":
    main()
