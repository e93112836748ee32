"""The offline dataset format (D4RL-like): layout, manifest, loading and writing episodes.

Layout written by `rllib data collect` (nothing is downloaded)::

    <out>/<task>/manifest.json                  return statistics, reference returns, provenance
    <out>/<task>/<dynamics>/<quality>/*.parquet one row per complete episode (column "item":
                                                the episode's state packed with msgpack_numpy,
                                                RLlib's `output_write_episodes=True` format)
    <out>/<task>/<dynamics>/policies/<name>/    RLModule checkpoints of the policies used

`task` is the env id's short name (`rllib_asor/HopperShift-v0` -> `hopper`); `dynamics` are
presets of `MujocoShiftEnv` (`original`, `body_mass` = mass x3, `density_10`); `quality` is
`random` (uniform actions), `medium` (a partially trained policy), `expert` (the best policy
of the run) or `medium-replay` (what training saw up to the medium snapshot). Policies are
trained per dynamics with PPO (default; ~10x cheaper per env step than RLlib's SAC on a small
CPU machine) or SAC (`rllib data collect --trainer`), for `--train-steps` env steps.

Normalised score (D4RL): 100 * (R - R_random) / (R_expert - R_random) with our own random and
expert datasets' mean episode returns under the same dynamics.

A task directory is written into a temporary sibling and renamed when complete, so a crash
leaves no half-written dataset behind.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

FORMAT = "rllib_asor.offline/v1"
MANIFEST = "manifest.json"
QUALITIES = ("random", "medium", "expert", "medium-replay")
DYNAMICS = ("original", "body_mass", "density_10")
HINT = "expected a dataset written by `rllib data collect`"
"""What a dataset error suggests (the one command that writes datasets)."""


def task_name(env_id: str) -> str:
    """Short task name of an env id: `rllib_asor/HopperShift-v0` -> `hopper`."""
    base = env_id.rsplit("/", 1)[-1]
    base = re.sub(r"-v\d+$", "", base)
    base = re.sub(r"Shift$", "", base)
    return base.lower()


def return_stats(episodes: Sequence[Any]) -> dict[str, Any]:
    """Episode-return statistics of complete episodes (what the manifest stores)."""
    returns = np.array([float(e.get_return()) for e in episodes], dtype=np.float64)
    lengths = np.array([len(e) for e in episodes], dtype=np.int64)
    if returns.size == 0:
        raise ValueError("no complete episodes to compute return statistics from")
    return {
        "num_episodes": int(returns.size),
        "num_steps": int(lengths.sum()),
        "return_mean": float(returns.mean()),
        "return_std": float(returns.std()),
        "return_min": float(returns.min()),
        "return_max": float(returns.max()),
        "length_mean": float(lengths.mean()),
    }


def write_episodes(episodes: Sequence[Any], path: Path) -> None:
    """Write complete episodes as parquet rows in RLlib's episode format (msgpack_numpy)."""
    import msgpack
    import msgpack_numpy as mnp
    import ray

    rows = [{"item": msgpack.packb(e.get_state(), default=mnp.encode)} for e in episodes]
    ray.data.from_items(rows).repartition(1).write_parquet(path.as_posix())


@dataclass(frozen=True)
class OfflineDataset:
    """A validated task directory: its manifest and the parquet dirs of the chosen parts."""

    root: Path
    manifest: dict[str, Any]
    paths: tuple[str, ...]
    dynamics: tuple[str, ...]
    qualities: tuple[str, ...]

    @property
    def env(self) -> str:
        return str(self.manifest["env"])

    @property
    def task(self) -> str:
        return str(self.manifest["task"])

    @property
    def num_steps(self) -> int:
        ds = self.manifest["datasets"]
        return sum(int(ds[d][q]["num_steps"]) for d in self.dynamics for q in self.qualities)


def read_manifest(root: str | os.PathLike[str]) -> dict[str, Any]:
    """The manifest of a task directory; ValueError naming the path if missing or invalid."""
    root = Path(root)
    if not root.is_dir():
        raise ValueError(f"offline dataset {root} does not exist or is not a directory; {HINT}")
    file = root / MANIFEST
    if not file.is_file():
        raise ValueError(f"no {MANIFEST} in {root}; {HINT}")
    try:
        manifest = json.loads(file.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ValueError(f"{file} is not valid JSON ({e}); {HINT}") from None
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        got = manifest.get("format") if isinstance(manifest, dict) else type(manifest).__name__
        raise ValueError(f"{file} has format {got!r}, expected {FORMAT!r}; {HINT}")
    for key in ("task", "env", "datasets", "reference_returns"):
        if key not in manifest:
            raise ValueError(f"{file} lacks the key {key!r}; {HINT}")
    return manifest


def load_dataset(
    path: str | os.PathLike[str],
    *,
    dynamics: str | Sequence[str] | None = None,
    quality: str | Sequence[str] | None = None,
) -> OfflineDataset:
    """Validate a dataset and select parts of it.

    `path` is a task dir (`data/offline/hopper`) or one part (`data/offline/hopper/original/
    medium`, which selects that part). `dynamics`/`quality` select parts (None: all present).
    """
    path = Path(path)
    root = path
    if not (path / MANIFEST).exists() and (path.parent.parent / MANIFEST).is_file():
        root = path.parent.parent
        if dynamics is None and quality is None:
            dynamics, quality = path.parent.name, path.name
    manifest = read_manifest(root)
    available = manifest["datasets"]
    dyns = _as_tuple(dynamics) or tuple(available)
    for d in dyns:
        if d not in available:
            raise ValueError(
                f"dynamics {d!r} not in {root}: allowed {' | '.join(available) or '(none)'}"
            )
    quals = _as_tuple(quality) or tuple(dict.fromkeys(q for d in dyns for q in available[d]))
    paths = []
    for d in dyns:
        for q in quals:
            if q not in available[d]:
                raise ValueError(
                    f"quality {q!r} not in {root}/{d}: allowed {' | '.join(available[d])}"
                )
            part = root / available[d][q]["path"]
            if not part.is_dir() or not any(part.glob("*.parquet")):
                raise ValueError(f"no parquet files in {part}; {HINT}")
            paths.append(part.resolve().as_posix())
    return OfflineDataset(root.resolve(), manifest, tuple(paths), dyns, quals)


def _as_tuple(value: str | Sequence[str] | None) -> tuple[str, ...]:
    if value is None:
        return ()
    return (value,) if isinstance(value, str) else tuple(value)
