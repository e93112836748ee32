"""Loading Tune results: trial folders, their per-iteration rows and params, method labels.

A trial folder holds ``result.json`` (one JSON object per training iteration) and
``params.json`` (the trial's algorithm config). Trials are labelled by env and method
(``PPO``, ``PPO+ASOR``, ``SAC+SRPO``, ...): the algorithm comes from the ``run`` that
`rllib train` records in the params (`RUN_KEY`), the ASOR mode from the params' ``asor``
block; `algo_name` and `asor_mode` say what they fall back to for results not written by
`rllib train`.
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

RESULT_FILE = "result.json"
PARAMS_FILE = "params.json"

KNOWN_ALGOS = (
    "APPO",
    "IMPALA",
    "PPO",
    "SAC",
    "DQN",
    "CQL",
    "IQL",
    "MARWIL",
    "BC",
    "TQC",
    "DreamerV3",
)
"""RLlib algorithm names recognised in trial and experiment folder names (longest match wins)."""

MODE_SUFFIX = {"asor": "+ASOR", "srpo": "+SRPO"}
"""Method suffix per ASOR partition mode; other modes become ``+ASOR(<mode>)``."""

RUN_KEY = "rllib_asor_run"
"""Params key under which `rllib train` records the experiment's ``run`` (``PPO``, ``SAC``, ...).

RLlib sets unknown top-level config keys as plain attributes (`AlgorithmConfig.update_from_dict`)
and validates none of them, so the key reaches ``params.json`` without changing training."""

SMOKE_KEY = "rllib_asor_smoke"
"""Params key `rllib train --test` and `rllib ab --test` set (True): a smoke run, too short to
judge; `rllib compare` labels its trials smoke and gives them no verdict."""
SMOKE_LABEL = " (smoke run)"
"""Appended to a smoke trial's env, so that smoke and real runs are never grouped together."""


@dataclass
class Trial:
    """One Tune trial: its folder, config and per-iteration flattened results."""

    path: Path
    experiment: str
    params: dict[str, Any]
    rows: list[dict[str, Any]]
    env: str = ""
    method: str = ""

    def series(self, key: str) -> np.ndarray:
        """Values of `key` per iteration as floats (NaN where absent or not a number)."""
        return np.array([_as_float(r.get(key)) for r in self.rows], dtype=float)

    def has(self, key: str) -> bool:
        """Whether any iteration reports a finite value for `key`."""
        return bool(np.isfinite(self.series(key)).any())

    def final(self, key: str, last_n: int) -> float:
        """Mean of the last `last_n` finite values of `key` (NaN if none)."""
        vals = self.series(key)
        vals = vals[np.isfinite(vals)]
        return float(np.mean(vals[-last_n:])) if vals.size else math.nan


# --------------------------------------------------------------------------- reading


def _as_float(v: Any) -> float:
    if isinstance(v, bool) or v is None:
        return math.nan
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def flatten(d: dict[str, Any], prefix: str = "") -> Iterator[tuple[str, Any]]:
    """Yield ``("a/b/c", value)`` for a nested result dict, skipping the ``config`` copy."""
    for k, v in d.items():
        if not prefix and k == "config":
            continue
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            yield from flatten(v, key + "/")
        else:
            yield key, v


def _read_rows(path: Path, notes: list[str]) -> list[dict[str, Any]]:
    """Parse a Tune ``result.json``; drop broken lines, keep the last report per iteration."""
    by_iter: dict[Any, dict[str, Any]] = {}
    bad = 0
    with path.open(encoding="utf-8") as f:
        for i, line in enumerate(f):
            line = line.strip()
            if not line:
                continue
            try:
                obj = json.loads(line)
            except json.JSONDecodeError:
                bad += 1
                continue
            if not isinstance(obj, dict):
                bad += 1
                continue
            row = dict(flatten(obj))
            # A restored trial re-reports iterations after its checkpoint: the later one wins.
            by_iter[row.get("training_iteration", f"line{i}")] = row
    if bad:
        notes.append(f"{path}: skipped {bad} unreadable line(s)")
    rows = list(by_iter.values())
    rows.sort(key=lambda r: _as_float(r.get("training_iteration")))
    return rows


def find_trials(results_dir: str | os.PathLike[str], notes: list[str] | None = None) -> list[Trial]:
    """All trial folders (holding ``result.json`` with at least one row) under `results_dir`,
    symlinks followed (each real folder once)."""
    root = Path(results_dir).expanduser()
    notes = notes if notes is not None else []
    if not root.is_dir():
        raise ValueError(f"results directory {str(root)!r} does not exist or is not a directory")
    trials: list[Trial] = []
    visited: set[str] = set()
    # Symlinked experiment folders are followed; a link back up the tree is not walked twice.
    for dirpath, dirnames, filenames in os.walk(root, followlinks=True):
        real = os.path.realpath(dirpath)
        if real in visited:
            dirnames[:] = []
            continue
        visited.add(real)
        dirnames[:] = sorted(d for d in dirnames if not d.startswith("checkpoint_"))
        if RESULT_FILE not in filenames:
            continue
        tdir = Path(dirpath)
        rows = _read_rows(tdir / RESULT_FILE, notes)
        if not rows:
            notes.append(f"{tdir}: empty {RESULT_FILE}, trial skipped")
            continue
        params: dict[str, Any] = {}
        if (tdir / PARAMS_FILE).is_file():
            try:
                loaded = json.loads((tdir / PARAMS_FILE).read_text(encoding="utf-8"))
                params = loaded if isinstance(loaded, dict) else {}
            except json.JSONDecodeError:
                notes.append(f"{tdir}: unreadable {PARAMS_FILE}")
        experiment = tdir.parent.name if tdir != root else root.name
        trials.append(Trial(path=tdir, experiment=experiment, params=params, rows=rows))
    if not trials:
        raise ValueError(f"no trial results ({RESULT_FILE}) found under {str(root)!r}")
    return trials


# --------------------------------------------------------------------------- grouping


def algo_name(trial: Trial) -> str:
    """Algorithm of a trial: the ``run`` that `rllib train` recorded in its params (`RUN_KEY`).

    Fallback, for results not written by `rllib train` (a plain Tune run, the benchmarks'
    function trainables, runs from before the key existed): a guess from the trial folder name
    (``PPO_CartPole-v1_...``, our ``AsorPPO_...``), else a token of the experiment name.
    """
    run = trial.params.get(RUN_KEY)
    if isinstance(run, str) and run:
        return run
    by_len = sorted(KNOWN_ALGOS, key=len, reverse=True)
    head = trial.path.name.split("_", 1)[0]
    # Our ASOR trainables are named Asor<run> (rllib_asor.rllib.trainable): AsorPPO -> PPO.
    bare = head[4:] if head.lower().startswith("asor") else head
    for name in by_len:
        if bare.lower() == name.lower():
            return name
    for token in re.split(r"[^A-Za-z0-9]+", trial.experiment):
        for name in by_len:
            if token.lower() == name.lower():
                return name
    return head or trial.experiment


def asor_block(params: dict[str, Any]) -> Any:
    """The ASOR settings in a trial's params (top-level ``asor`` or ``learner_config_dict.asor``)."""
    if "asor" in params and params["asor"] is not None:
        return params["asor"]
    lcd = params.get("learner_config_dict")
    if isinstance(lcd, dict) and lcd.get("asor") is not None:
        return lcd["asor"]
    return None


def asor_mode(params: dict[str, Any]) -> str | None:
    """ASOR partition mode of a trial, or None when the trial does not use ASOR: the ``mode``
    of the params' ``asor`` block (a dict, as `rllib train` and `with_asor` write it)."""
    block = asor_block(params)
    if block is None or block is False:
        return None
    if isinstance(block, dict):
        return str(block.get("mode", "asor"))
    # Fallback for params not written by `rllib train` (it writes the block as a dict): Tune
    # writes objects it cannot serialise as their repr, e.g. "AsorConfig(..., mode='srpo', ...)".
    m = re.search(r"\bmode\s*[=:]\s*['\"]?(\w+)", str(block))
    return m.group(1) if m else "asor"


def method_name(trial: Trial) -> str:
    """``PPO``, ``PPO+ASOR``, ``SAC+SRPO``, ``PPO+ASOR(count)``, ``MAPLE+DARA`` (a ``dara``
    block: MAPLE's and MOPO's ``dara_settings``), ..."""
    name = algo_name(trial) + ("+DARA" if trial.params.get("dara_settings") else "")
    mode = asor_mode(trial.params)
    if mode is None:
        return name
    return name + MODE_SUFFIX.get(mode, f"+ASOR({mode})")


def lookup(params: dict[str, Any], dotted: str) -> Any:
    """Value at a dotted key in params (also tried under ``learner_config_dict``); KeyError if absent."""
    for base in (params, params.get("learner_config_dict")):
        cur: Any = base
        for part in dotted.split("."):
            if isinstance(cur, dict) and part in cur:
                cur = cur[part]
            else:
                break
        else:
            return cur
    raise KeyError(dotted)


def is_smoke(params: dict[str, Any]) -> bool:
    """Whether a trial's params mark it a smoke run (`SMOKE_KEY` truthy)."""
    return bool(params.get(SMOKE_KEY))


def assign_groups(trials: Iterable[Trial], group_by: str | None = None) -> None:
    """Set each trial's ``env`` (with `SMOKE_LABEL` for a smoke run) and ``method``
    (``KEY=value`` when `group_by` is given)."""
    for t in trials:
        env = t.params.get("env")
        t.env = str(env) if env not in (None, "") else "unknown-env"
        if is_smoke(t.params):
            t.env += SMOKE_LABEL
        if group_by:
            try:
                value = lookup(t.params, group_by)
            except KeyError:
                value = "<missing>"
            t.method = (
                f"{group_by}={json.dumps(value) if isinstance(value, list | dict) else value}"
            )
        else:
            t.method = method_name(t)
