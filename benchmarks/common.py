"""What every speed benchmark needs: a quiet local Ray on a small machine, atomic JSON writes,
interleaved timing and paired ratios."""

from __future__ import annotations

import atexit
import gc
import json
import os
from collections.abc import Callable
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
    """Write `data` as compact JSON to `path` atomically (a temp file renamed into place), so
    an interrupted benchmark never leaves a half-written run file that a rerun would skip."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(data, separators=(",", ":")))
    os.replace(tmp, path)


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
