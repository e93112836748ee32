"""What every study runner shares: resumable run files (`studies.lib.run_files`), partial saves
of unfinished runs, the (method, seed) grid on Ray Tune, and table cells. Ray start-up and atomic
JSON writes are the speed benchmarks' (`benchmarks.common`), re-exported here so a study imports
one module."""

from __future__ import annotations

import json
import math
import shutil
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import start_local_ray, write_json
from studies.lib.run_files import existing, read_run, run_file, write_run

__all__ = [
    "load_partial",
    "mean_std",
    "run_if_missing",
    "round_floats",
    "run_method_seed_grid",
    "runs_made_otherwise",
    "save_partial",
    "start_local_ray",
    "write_json",
    "window_means",
    "declines",
    "write_summary",
]


def write_summary(
    folder: Path,
    summarise: Callable[[Path], dict[str, Any]],
    table: Callable[[dict[str, Any]], str],
) -> str:
    """A study's small results from FOLDER/runs: `summarise(runs)` into FOLDER/summary.json
    and `table(summary)` into FOLDER/table.md; returns the table."""
    res = summarise(folder / "runs")
    (folder / "summary.json").write_text(json.dumps(res, indent=1))
    (folder / "table.md").write_text(md := table(res))
    return md


def window_means(
    steps: Sequence[float], values: Sequence[float | None], every: int, stop: int
) -> list[float | None]:
    """The mean of the finite `values` per `every` env steps, windows (end − every, end] for
    end = every, 2·every, … up to `stop`; None for a window without one (an iteration where no
    episode ended logs NaN)."""
    out = []
    for end in range(every, stop + 1, every):
        xs = [
            v
            for s, v in zip(steps, values, strict=True)
            if end - every < s <= end and v is not None and math.isfinite(v)
        ]
        out.append(sum(xs) / len(xs) if xs else None)
    return out


def declines(
    curve: Sequence[Sequence[float]],
    window: int = 125_000,
    stop: int = 2_000_000,
    peak: float = 0.6,
    low: float = 0.4,
) -> bool:
    """Whether a run's training success declines (studies/race_scale_2m's reading): its mean
    per `window` env steps up to `stop` (`curve` rows are [env steps, success, ...]) reaches
    `peak` in some window and is below `low` over the last one."""
    w = window_means([c[0] for c in curve], [c[1] for c in curve], window, stop)
    return max((x for x in w if x is not None), default=0.0) >= peak and (w[-1] or 0.0) < low


def round_floats(value: Any, digits: int = 6) -> Any:
    """`value` (JSON-like) with every float that is not a whole number rounded to `digits`
    significant digits; whole numbers (step counts), NaN and ±inf are kept as they are. For a
    run's raw records that no table reads (its training curve, per-episode metrics): a third to
    a half of their bytes, no visible change."""
    if isinstance(value, float):
        if not math.isfinite(value) or value.is_integer():
            return value
        return float(f"{value:.{digits}g}")
    if isinstance(value, dict):
        return {k: round_floats(v, digits) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [round_floats(v, digits) for v in value]
    return value


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
    """One sequential benchmark run: skipped when its run file (`run_files.run_file`) exists (a
    rerun resumes where it stopped), else `run()`, its result written to `path`, progress
    printed."""
    if existing(path):
        return
    print(f"run {label}", flush=True)
    res = run()
    write_run(path, res)
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
    """Run files OUT/runs/<method>-<seed> that exist and record other `settings` than these.
    A rerun keeps finished runs, so without this check one folder could silently mix settings.
    A key a file lacks counts as `defaults[key]`, or is not compared."""
    defaults = defaults or {}
    clash = []
    for name in names:
        for seed in seeds:
            path = existing(run_file(out / "runs", f"{name}-{seed}"))
            if path is None:
                continue
            run = read_run(path)
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
    """One Tune trial per (method, seed) whose run file `out/runs/<method>-<seed>` is missing, so
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
        if not existing(run_file(out / "runs", f"{n}-{s}"))
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
