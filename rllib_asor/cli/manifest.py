"""What an experiment folder holds: a record written before Tune starts, checked on every rerun.

`rllib train` and `rllib ab` write ``rllib_asor_experiment.json`` into the experiment folder:
the run, env, stop, every config value after translation and command-line overrides, the
`asor:` block, checkpoints and (`rllib ab`) the seeds run so far. A rerun into a folder that
holds a record:

- the same experiment: resumed (finished trials are kept; `rllib ab` runs only the seeds the
  folder lacks);
- anything else: refused in one line naming each difference and the ways out, `--name NAME`
  (another folder) or `--fresh` (the old folder is renamed ``NAME.replaced-<time>``, nothing is
  deleted, and the run starts over).

A folder that Tune wrote but that holds no record (a run from before the record existed) cannot be
checked and is refused the same way. `--test` runs are smoke runs: they go to ``NAME-test``, never
to a folder of real runs, and each one starts that folder over.
"""

from __future__ import annotations

import fcntl
import json
import os
import re
import shutil
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from rllib_asor.cli.errors import UsageError
from rllib_asor.report.files import atomic_write

RECORD_FILE = "rllib_asor_experiment.json"
SMOKE_SUFFIX = "-test"
MAX_SHOWN = 4
"""Differences named in the refusal (the rest are counted)."""
LOCK_FILE = ".rllib_asor.lock"
"""Held (flock) by the command running in the folder, for the life of its process."""
_MISSING = object()
_HELD: dict[str, int] = {}
"""Folder -> the open lock file of a folder this process runs in."""


def describe(exp: Any, smoke: bool) -> dict[str, Any]:
    """The record of one experiment as it would run now (JSON values, keys sorted)."""
    return canonical({
        "run": exp.run,
        "env": exp.env,
        "stop": exp.stop,
        "config": exp.config,
        "asor": exp.asor,
        "num_samples": exp.num_samples,
        "checkpoint_config": exp.checkpoint_config,
        "smoke": smoke,
    })  # fmt: skip


def canonical(value: Any) -> Any:
    """`value` as JSON would give it back (tuples as lists, keys as strings); a function or
    class as its import path, any other object as its repr without memory addresses."""
    return json.loads(json.dumps(value, sort_keys=True, default=_stable))


def _stable(obj: Any) -> str:
    if hasattr(obj, "__qualname__") and hasattr(obj, "__module__"):
        return f"{obj.__module__}.{obj.__qualname__}"
    return re.sub(r" at 0x[0-9a-fA-F]+", "", repr(obj))


def _flat(value: Any, prefix: str = "") -> Iterator[tuple[str, Any]]:
    if isinstance(value, Mapping) and value:
        for k in sorted(value):
            yield from _flat(value[k], f"{prefix}.{k}" if prefix else str(k))
    else:
        yield prefix, value


def _shown(value: Any) -> str:
    return "(unset)" if value is _MISSING else json.dumps(value)


def differences(held: Mapping[str, Any], wanted: Mapping[str, Any]) -> list[str]:
    """Each dotted key whose value differs, as ``key: held -> wanted``."""
    old, new = dict(_flat(held)), dict(_flat(wanted))
    return [
        f"{key}: {_shown(old.get(key, _MISSING))} -> {_shown(new.get(key, _MISSING))}"
        for key in sorted(old.keys() | new.keys())
        if old.get(key, _MISSING) != new.get(key, _MISSING)
    ]


def read(path: str) -> dict[str, Any] | None:
    """The record in the folder `path`, None when there is none."""
    try:
        with open(os.path.join(path, RECORD_FILE), encoding="utf-8") as f:
            record = json.load(f)
    except FileNotFoundError:
        return None
    except (OSError, json.JSONDecodeError) as e:
        raise UsageError(f"unreadable record of what the folder holds ({e}); {ways_out()}",
                         source=os.path.join(path, RECORD_FILE)) from None  # fmt: skip
    return record if isinstance(record, dict) else None


def write(path: str, record: Mapping[str, Any]) -> None:
    """Write the record into the folder `path` (created if missing), atomically."""
    os.makedirs(path, exist_ok=True)
    text = json.dumps(record, indent=1, sort_keys=True) + "\n"
    atomic_write(Path(path) / RECORD_FILE, text.encode())


def ways_out() -> str:
    return "allowed: the same settings, --name NAME (another folder) or --fresh (start over)"


def holds_results(path: str) -> bool:
    """Whether the folder holds anything (a Tune experiment, trials, a record) but its lock."""
    return os.path.isdir(path) and any(e.name != LOCK_FILE for e in os.scandir(path))


def refuse_changed(path: str, held: Mapping[str, Any], wanted: Mapping[str, Any]) -> None:
    """UsageError naming every difference between `held` and `wanted` (None when equal)."""
    diffs = _per_arm(differences(held, wanted), {**held, **wanted}.get("arms") or {})
    if not diffs:
        return
    shown = "; ".join(diffs[:MAX_SHOWN])
    more = f" (and {len(diffs) - MAX_SHOWN} more)" if len(diffs) > MAX_SHOWN else ""
    raise UsageError(f"holds a different experiment: {shown}{more}; {ways_out()}", source=path)


def _per_arm(diffs: list[str], arms: Mapping[str, Any]) -> list[str]:
    """`rllib ab`'s differences: ``arms.<label>.key`` as ``key`` when every arm has it, else as
    ``<label>: key``."""
    out: dict[str, set[str]] = {}
    for d in diffs:
        label = next((a for a in arms if d.startswith(f"arms.{a}.")), None)
        rest = d[len(f"arms.{label}.") :] if label else d
        out.setdefault(rest, set()).add(label or "")
    return [
        d if labels == set(arms) or labels == {""} else f"{', '.join(sorted(labels))}: {d}"
        for d, labels in out.items()
    ]


def refuse_unrecorded(path: str) -> None:
    raise UsageError(
        "holds results without a record of what was run (written before rllib-asor kept one), "
        f"so a rerun cannot be checked against them; {ways_out()}",
        source=path,
    )


def move_aside(path: str) -> str | None:
    """Rename the folder `path` to ``path.replaced-<time>`` (nothing deleted); the new name."""
    if not os.path.exists(path):
        return None
    stamp = time.strftime("%Y%m%d-%H%M%S")
    target, n = f"{path}.replaced-{stamp}", 1
    while os.path.exists(target):
        n += 1
        target = f"{path}.replaced-{stamp}-{n}"
    os.rename(path, target)
    return target


def start_smoke(path: str) -> None:
    """A smoke folder starts over on each `--test` run (it never holds real runs)."""
    record = read(path)
    if holds_results(path) and (record is None or not _is_smoke(record)):
        raise UsageError(
            "holds runs that are not --test smoke runs; a --test run never shares their folder; "
            "allowed: --name NAME (another folder)",
            source=path,
        )
    _release(path)
    shutil.rmtree(path, ignore_errors=True)


def _is_smoke(record: Mapping[str, Any]) -> bool:
    return any(v is True for k, v in _flat(record) if k == "smoke" or k.endswith(".smoke"))


def _release(path: str) -> None:
    fd = _HELD.pop(os.path.abspath(path), None)
    if fd is not None:
        os.close(fd)


def lock(path: str) -> None:
    """Hold the folder's lock for the rest of this process (UsageError when another process
    holds it: a command running in that folder now)."""
    key = os.path.abspath(path)
    if key in _HELD:
        return
    os.makedirs(path, exist_ok=True)
    fd = os.open(os.path.join(path, LOCK_FILE), os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise UsageError(
            "another rllib command is running in this folder now; allowed: wait for it to end, "
            "or --name NAME (another folder)",
            source=path,
        ) from None
    _HELD[key] = fd


def prepare(
    path: str, wanted: Mapping[str, Any], *, fresh: bool, smoke: bool
) -> tuple[dict[str, Any], bool]:
    """Make the folder `path` ready for a run of `wanted` (UsageError when it holds another
    experiment, compared without ``seeds``, or another process runs in it now). Returns the
    record the run goes on from (`wanted`, with the held ``seeds`` when resumed) and whether the
    folder holds that experiment already. The folder stays locked while this process lives."""
    record = dict(wanted)
    if os.path.isdir(path):
        lock(path)  # nothing is moved or removed under a running command
    if smoke:
        start_smoke(path)
    elif fresh:
        _release(path)
        moved = move_aside(path)
        if moved:
            print(f"rllib: --fresh: the previous results moved to {moved}", flush=True)
    else:
        held = read(path)
        if held is None and holds_results(path):
            refuse_unrecorded(path)
        if held is not None:
            refuse_changed(path, _without(held, "seeds"), _without(wanted, "seeds"))
            record = {**held, **wanted, "seeds": held.get("seeds", [])}
            write(path, record)
            return record, True
    lock(path)
    write(path, record)
    return record, False


def _without(record: Mapping[str, Any], key: str) -> dict[str, Any]:
    return {k: v for k, v in record.items() if k != key}
