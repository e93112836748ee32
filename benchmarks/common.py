"""What every benchmark needs: a quiet local Ray on a small machine, and a bootstrap CI."""

from __future__ import annotations

import atexit
import gc
import json
import os
import shutil
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np


def start_local_ray(num_cpus: int = 2) -> None:
    """A fresh local Ray (ignores any `ray start` cluster), one torch thread per process.

    On 2 cores torch's intra-op threads fight the env runners: one thread is several times
    faster under load (docs/race_training.md).
    """
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    os.environ.setdefault("RAY_memory_monitor_refresh_ms", "0")
    import ray
    import torch

    torch.set_num_threads(1)
    ray.init(
        address="local",
        num_cpus=num_cpus,
        include_dashboard=False,
        log_to_driver=False,
        configure_logging=False,
    )
    # Registered after Ray's own shutdown hook, so it runs first: an algorithm left in a
    # reference cycle (CQL's Ray Data batch iterator) is collected while Ray is still up, not
    # after its shutdown, where it printed a harmless but alarming "Ray is not initialized".
    atexit.register(gc.collect)


def write_json(path: Path, data: Any) -> None:
    """Write `data` as JSON to `path` atomically (a temp file renamed into place), so an
    interrupted benchmark never leaves a half-written run file that a rerun would skip."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(data))
    os.replace(tmp, path)


def save_partial(partial: Path, state: dict[str, Any], save: Callable[[Path], None]) -> None:
    """Save an unfinished run: `save(folder)` writes the checkpoint into an empty folder, the
    one the current state does not name (`algo-a` / `algo-b` in turn); then the state naming
    it replaces the old one atomically; then the previous checkpoint goes. A run killed at any
    moment keeps a state and the complete checkpoint it names (`load_partial`)."""
    partial.mkdir(parents=True, exist_ok=True)
    current = load_partial(partial)
    old = current[1] if current else None
    name = "algo-b" if old == partial / "algo-a" else "algo-a"
    shutil.rmtree(partial / name, ignore_errors=True)
    (partial / name).mkdir()
    save(partial / name)
    write_json(partial / "state.json", {**state, "checkpoint": name})
    if old is not None and old != partial:
        shutil.rmtree(old, ignore_errors=True)


def load_partial(partial: Path) -> tuple[dict[str, Any], Path] | None:
    """The last `save_partial` of a run: (its state, its checkpoint folder), or None if the run
    was never saved. A state without a `checkpoint` (saved before the folders alternated)
    names `partial` itself."""
    state_file = partial / "state.json"
    if not state_file.exists():
        return None
    state = json.loads(state_file.read_text())
    return state, partial / state.get("checkpoint", "")


def run_if_missing(path: Path, label: str, run: Callable[[], dict[str, Any]]) -> None:
    """One sequential benchmark run: skipped when its run file exists (a rerun resumes where
    it stopped), else `run()`, its result written atomically to `path`, progress printed."""
    if path.exists():
        return
    print(f"run {label}", flush=True)
    res = run()
    write_json(path, res)
    print(f"  eval {res['eval']} wall {res['wall_s']:.0f}s", flush=True)


def mean_std(xs: Sequence[float]) -> str:
    """Table cell "mean ± std" (sample std over runs; 0 for a single run), one decimal."""
    sd = float(np.std(xs, ddof=1)) if len(xs) > 1 else 0.0
    return f"{np.mean(xs):.1f} ± {sd:.1f}"


def runs_made_otherwise(
    out: Path,
    names: Iterable[str],
    seeds: Iterable[int],
    settings: dict[str, Any],
    defaults: dict[str, Any] | None = None,
) -> list[str]:
    """Run files OUT/runs/<method>-<seed>.json that exist and record other `settings` than
    these. A rerun keeps finished runs, so without this check one folder could silently mix
    settings. A key a file lacks counts as `defaults[key]`, or is not compared."""
    import json

    defaults = defaults or {}
    clash = []
    for name in names:
        for seed in seeds:
            path = out / "runs" / f"{name}-{seed}.json"
            if not path.exists():
                continue
            run = json.loads(path.read_text())
            for key, want in settings.items():
                if key not in run and key not in defaults:
                    continue
                if (have := run.get(key, defaults.get(key))) != want:
                    clash.append(f"{path.name} ({key}={have!r})")
                    break
    return clash


def run_method_seed_grid(
    trainable: Callable[[dict[str, Any]], Any],
    methods: Iterable[tuple[str, dict[str, Any] | None]],
    seeds: Iterable[int],
    shared: dict[str, Any],
    out: Path,
    cpus_per_trial: int = 1,
) -> None:
    """One Tune trial per (method, seed) whose `out/runs/<method>-<seed>.json` is missing, so
    an interrupted benchmark resumes where it stopped. A trial holds `cpus_per_trial` CPUs: one
    for itself, the rest for the env runners it starts.

    Each trial gets `{"spec": {"method", "asor", "seed", "args": shared, "out"}}`.
    """
    import time

    from ray import tune

    methods = list(methods)
    specs = [
        {"method": n, "asor": a, "seed": s, "args": shared, "out": str(out)}
        for s in seeds
        for n, a in methods
        if not (out / "runs" / f"{n}-{s}.json").exists()
    ]
    t0 = time.time()
    if specs:
        tune.Tuner(
            tune.with_resources(
                trainable,
                tune.PlacementGroupFactory([{"CPU": 1}] * cpus_per_trial),
            ),
            param_space={"spec": tune.grid_search(specs)},
            run_config=tune.RunConfig(storage_path=str(out / "tune"), verbose=0),
        ).fit()
    print(f"trained {len(specs)} runs in {time.time() - t0:.0f} s")


def time_interleaved(
    runners: dict[str, Any], rounds: int, block: Callable[[str], int]
) -> dict[str, list[dict[str, float]]]:
    """Time `runners` (objects with `.steps` and `.run(n)`) in interleaved rounds: each round
    runs every runner for `block(name)` env steps in turn, so load drift hits them all alike.
    Returns per runner and round {"steps", "wall_s", "steps_per_s"}."""
    import time

    out: dict[str, list[dict[str, float]]] = {n: [] for n in runners}
    for r in range(rounds):
        for name, runner in runners.items():
            before, t0 = runner.steps, time.perf_counter()
            runner.run(block(name))
            wall = time.perf_counter() - t0
            done = runner.steps - before
            out[name].append({"steps": done, "wall_s": wall, "steps_per_s": done / wall})
            print(f"round {r} {name}: {done} steps in {wall:.1f}s = {done / wall:.1f} steps/s")
    return out


def median_paired_ratios(rounds: dict[str, list[dict[str, float]]], base: str) -> dict[str, float]:
    """Per runner, the median over rounds of its rate ÷ `base`'s rate in the same round (less
    sensitive to load drift between rounds than the ratio of totals)."""
    return {
        n: float(
            np.median(
                [x["steps_per_s"] / b["steps_per_s"] for x, b in zip(rs, rounds[base], strict=True)]
            )
        )
        for n, rs in rounds.items()
    }
