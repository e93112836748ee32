"""mutmut's verdicts kept in the repository, so that a mutation run outlives its build folder.

mutmut keeps each mutant's verdict in `build/mutation/<package>/mutants/<file>.meta`, beside the
hash of every function's source; build/ is ignored by git, so a fresh checkout starts every
package from zero (about 2½ hours for the glue on 2 cores). `save` copies the verdicts and the
function hashes of one package's build into benchmarks/mutation/verdicts/<package>.json (one
small file, committed with the work); `restore` writes them back as mutmut's `.meta` files into
a build that has none. mutmut then keeps a verdict only where the function's hash is unchanged
(its own rule for a second run in the same folder) and tests every other mutant.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

HERE = Path(__file__).resolve().parent
RECORDS = HERE / "verdicts"
KEPT = ("exit_code_by_key", "hash_by_function_name")
"""What a record keeps of each `.meta`; durations and type-check notes are mutmut's to redo."""


def record_path(package: str, records: Path = RECORDS) -> Path:
    return records / f"{package}.json"


def save(package: str, build: Path, records: Path = RECORDS) -> int:
    """Write the verdicts of `build/mutants/**.meta` to the package's record (atomically);
    returns how many mutants have a verdict. A build without `.meta` files writes nothing."""
    files = {}
    for meta in sorted((build / "mutants").rglob("*.py.meta")):
        data = json.loads(meta.read_text())
        rel = meta.relative_to(build / "mutants").as_posix()[: -len(".meta")]
        files[rel] = {key: data.get(key, {}) for key in KEPT}
    if not files:
        return 0
    path = record_path(package, records)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps({"package": package, "files": files}, indent=0, sort_keys=True))
    os.replace(tmp, path)
    return sum(v is not None for f in files.values() for v in f["exit_code_by_key"].values())


def restore(package: str, build: Path, records: Path = RECORDS) -> int:
    """Write the package's record as mutmut `.meta` files into `build/mutants/`, unless that
    folder exists (a build's own verdicts come first); returns how many verdicts it wrote."""
    path = record_path(package, records)
    if (build / "mutants").exists() or not path.exists():
        return 0
    record = json.loads(path.read_text())
    if record.get("package") != package:
        raise ValueError(f"{path} holds the verdicts of {record.get('package')!r}, not {package!r}")
    written = 0
    for rel, data in record["files"].items():
        meta = build / "mutants" / f"{rel}.meta"
        meta.parent.mkdir(parents=True, exist_ok=True)
        meta.write_text(
            json.dumps(
                {
                    **{key: data[key] for key in KEPT},
                    "type_check_error_by_key": {},
                    "durations_by_key": {},
                    "estimated_durations_by_key": {},
                }
            )
        )
        written += sum(v is not None for v in data["exit_code_by_key"].values())
    return written
