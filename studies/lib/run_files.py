"""A study's run files: one finished run per file, OUT/runs/<name>.json.gz, compact JSON in
gzip (a fifth of the bytes; `zcat FILE` prints it). Written atomically, so an interrupted study
never leaves a half-written file that a rerun would skip. Files written before the compression,
OUT/runs/<name>.json, are read alike.

    python -m studies.lib.run_files compress [FOLDER ...]   # every runs/*.json under FOLDERs
                                                            # (default studies/) to .json.gz
"""

from __future__ import annotations

import argparse
import gzip
import json
import os
from pathlib import Path
from typing import Any

SUFFIX = ".json.gz"
LEGACY_SUFFIX = ".json"


def run_file(runs: Path, name: str) -> Path:
    """Where the run NAME (e.g. "ppo-3") of the folder RUNS is written."""
    return Path(runs) / f"{name}{SUFFIX}"


def run_name(path: Path) -> str:
    """The run's name from its file name, either form."""
    name = Path(path).name
    for suffix in (SUFFIX, LEGACY_SUFFIX):
        if name.endswith(suffix):
            return name[: -len(suffix)]
    raise ValueError(f"{path}: not a run file; allowed names end in {SUFFIX} or {LEGACY_SUFFIX}")


def existing(path: Path) -> Path | None:
    """The file that holds the run of `run_file(...)` path PATH: PATH itself, or the same run
    written before the compression (<name>.json); None when the run has not finished."""
    path = Path(path)
    legacy = path.with_name(run_name(path) + LEGACY_SUFFIX)
    return next((p for p in (path, legacy) if p.is_file()), None)


def read_run(path: Path) -> dict[str, Any]:
    """One run file's record, either form."""
    path = Path(path)
    raw = gzip.decompress(path.read_bytes()) if path.name.endswith(SUFFIX) else path.read_bytes()
    return json.loads(raw)


def write_run(path: Path, record: dict[str, Any]) -> None:
    """Write RECORD to the run file PATH (a `run_file(...)` path) atomically: a temporary file
    renamed into place. The gzip header carries no time, so equal records give equal bytes."""
    path = Path(path)
    if not path.name.endswith(SUFFIX):
        raise ValueError(f"{path}: a run file is written as <name>{SUFFIX}")
    path.parent.mkdir(parents=True, exist_ok=True)
    _gzip_into(path, json.dumps(record, separators=(",", ":")).encode())


def _gzip_into(path: Path, text: bytes) -> None:
    """TEXT gzipped (no time in the header) into PATH through a temporary file, replaced only
    once the temporary file decompresses to TEXT."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(gzip.compress(text, compresslevel=9, mtime=0))
    if gzip.decompress(tmp.read_bytes()) != text:
        raise SystemExit(f"{path}: the compressed copy differs; nothing replaced")
    os.replace(tmp, path)


def run_paths(runs: Path, pattern: str = "*") -> list[Path]:
    """The run files of the folder RUNS whose names match PATTERN (a glob over run names),
    either form, sorted by run name. A run held in both forms is an error: which one counts
    would be a guess."""
    runs = Path(runs)
    paths = sorted(runs.glob(pattern + SUFFIX)) + sorted(runs.glob(pattern + LEGACY_SUFFIX))
    by_name: dict[str, Path] = {}
    for path in paths:
        if (name := run_name(path)) in by_name:
            raise SystemExit(
                f"{runs}: run {name!r} is held twice ({by_name[name].name}, {path.name}); "
                "keep one of them"
            )
        by_name[name] = path
    return [by_name[n] for n in sorted(by_name)]


def read_runs(runs: Path, pattern: str = "*") -> list[dict[str, Any]]:
    """The records of `run_paths(RUNS, PATTERN)`, in that order."""
    return [read_run(p) for p in run_paths(runs, pattern)]


def compress(folder: Path) -> list[Path]:
    """Every <name>.json run file in a `runs/` folder under FOLDER rewritten as <name>.json.gz
    (the same JSON text, checked before the old file goes); returns the files written."""
    written = []
    for old in sorted(Path(folder).rglob("runs/*" + LEGACY_SUFFIX)):
        new = old.with_name(run_name(old) + SUFFIX)
        _gzip_into(new, old.read_bytes())
        old.unlink()
        written.append(new)
    return written


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    comp = sub.add_parser("compress", help="rewrite runs/*.json files as runs/*.json.gz")
    comp.add_argument("folders", nargs="*", type=Path, default=[Path("studies")])
    args = parser.parse_args(argv)
    for folder in args.folders:
        if not folder.is_dir():
            parser.error(f"{folder}: no such folder; allowed: a study folder or studies/")
        n = len(compress(folder))
        print(f"{folder}: {n} run files compressed")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
