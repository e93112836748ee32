"""CLI soak: every tuned example with `--test` and `rllib ab --seeds 2 --test`, repeated, several
at once, every log kept; finds tracebacks that appear only under load.

    python -m benchmarks.soak_cli                          # 5 rounds, 2 at once (hours on 2 cores)
    python -m benchmarks.soak_cli --rounds 1 --parallel 2  # one round
    python -m benchmarks.soak_cli --only lava              # files whose path contains "lava"

Each run writes `<out>/<round>/<name>.log` (stdout and stderr together) and `<name>.json` (the
command, exit status, seconds, and the tracebacks found: their last line each) as soon as it
ends; a rerun skips the runs whose JSON exists, so a cut-off soak resumes. A run counts as
clean when it exits 0 (or with the one-line refusal, exit 2, that a file needing data or a GPU
is expected to give) and prints no traceback. `<out>/summary.json` and the table printed at the
end count runs, failures and tracebacks per command. Exit status 0 when every run is clean.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
AB_FILE = "tuned_examples/lava/ppo-asor.yaml"
TRACEBACK = re.compile(r"^Traceback \(most recent call last\):", re.M)
IGNORED = re.compile(r"^Exception ignored in.*\n(?!Traceback)(.*)", re.M)  # no frames shown
ANSI = re.compile(r"\x1b\[[0-9;]*m")  # Ray colours the prefix even into a pipe
# "(EnvRunner pid=12, ip=..) ", also "(AsorPPO(env=...; multi-agent=False) pid=12) ": an actor
# prefix is its repr, which may hold parentheses
RAY_PREFIX = re.compile(r"^\((?:[^\n]*? )?pid=\d+(?:, ip=[^)\n]*)?\) ?", re.M)


def commands(only: str | None) -> list[tuple[str, list[str]]]:
    """(name, argv after `rllib`) for every tuned example's `--test`, then `rllib ab`."""
    runs = [
        (str(p.relative_to(ROOT / "tuned_examples").with_suffix("")).replace("/", "__"),
         ["train", "file", str(p.relative_to(ROOT)), "--test"])
        for p in sorted((ROOT / "tuned_examples").rglob("*.yaml"))
    ]  # fmt: skip
    runs.append(("ab__lava_ppo-asor", ["ab", AB_FILE, "--seeds", "2", "--test"]))
    return [(n, a) for n, a in runs if only is None or only in " ".join(a)]


def tracebacks(text: str) -> list[str]:
    """The last line of each Python traceback in `text` (the exception it ended with), also of
    those Ray relays from its workers with a `(name pid=N)` prefix on every line, and of each
    "Exception ignored in ..." that Python printed without frames."""
    found = []
    text = RAY_PREFIX.sub("", ANSI.sub("", text))
    for m in TRACEBACK.finditer(text):
        lines = text[m.end() :].splitlines()
        # the exception line: the first non-indented line after the frames
        last = next((ln for ln in lines[1:] if ln and not ln.startswith((" ", "\t"))), "?")
        found.append(last.strip()[:300])
    found += [m.group(1).strip()[:300] or "?" for m in IGNORED.finditer(text)]
    return found


def run_one(name: str, argv: list[str], out: Path, timeout_s: int, storage: Path) -> dict:
    """Run `rllib <argv>` once; write its log and JSON (the JSON last, so it marks a finished run)."""
    result_path = out / f"{name}.json"
    if result_path.exists():
        return json.loads(result_path.read_text())
    rllib = Path(sys.executable).with_name("rllib")
    cmd = [str(rllib), *argv, "--storage-path", str(storage / out.name / name)]
    start = time.monotonic()
    try:
        proc = subprocess.run(
            cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout_s,
            env={**os.environ, "OMP_NUM_THREADS": "1"},
        )  # fmt: skip
        code, text = proc.returncode, proc.stdout + proc.stderr
    except subprocess.TimeoutExpired as e:
        code = "timeout"
        text = (e.stdout or b"").decode(errors="replace") + (e.stderr or b"").decode(
            errors="replace"
        )
    (out / f"{name}.log").write_text(text)
    found = tracebacks(text)
    record = {
        "name": name,
        "command": "rllib " + " ".join(argv),
        "exit": code,
        "seconds": round(time.monotonic() - start, 1),
        "tracebacks": found,
        "clean": code in (0, 2) and not found,
    }
    tmp = result_path.with_suffix(".tmp")
    tmp.write_text(json.dumps(record, indent=1))
    tmp.replace(result_path)
    return record


def summarise(records: list[dict]) -> dict[str, Any]:
    """Per command: runs, exits other than 0, runs with a traceback, the tracebacks' last lines."""
    per: dict[str, dict[str, Any]] = {}
    for r in records:
        s = per.setdefault(r["command"], {"runs": 0, "nonzero": 0, "with_traceback": 0, "seen": []})
        s["runs"] += 1
        s["nonzero"] += r["exit"] != 0
        s["with_traceback"] += bool(r["tracebacks"])
        s["seen"] += [t for t in r["tracebacks"] if t not in s["seen"]]
    return per


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--parallel", type=int, default=2)
    p.add_argument("--only", default=None, help="only commands containing this text")
    p.add_argument("--timeout", type=int, default=900, help="seconds per run")
    p.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out" / "soak_cli")
    args = p.parse_args(argv)
    if args.rounds < 1 or args.parallel < 1:
        p.error("--rounds and --parallel: allowed integers >= 1")
    runs = commands(args.only)
    if not runs:
        p.error(f"--only {args.only!r} matches no command")
    storage = args.out / "results"
    jobs = []
    for r in range(args.rounds):
        folder = args.out / f"round{r}"
        folder.mkdir(parents=True, exist_ok=True)
        jobs += [(name, a, folder) for name, a in runs]
    records = []
    with ThreadPoolExecutor(args.parallel) as pool:
        futures = [pool.submit(run_one, n, a, f, args.timeout, storage) for n, a, f in jobs]
        for fut in futures:
            rec = fut.result()
            records.append(rec)
            mark = "ok" if rec["clean"] else f"exit {rec['exit']}, {len(rec['tracebacks'])} tb"
            print(f"{rec['seconds']:>7.1f} s  {mark:<16} {rec['command']}", flush=True)
    per = summarise(records)
    (args.out / "summary.json").write_text(json.dumps(per, indent=1))
    bad = sum(not r["clean"] for r in records)
    print(f"\n{len(records)} runs, {bad} not clean, "
          f"{sum(bool(r['tracebacks']) for r in records)} with a traceback")  # fmt: skip
    for cmd, s in per.items():
        if s["nonzero"] or s["with_traceback"]:
            print(f"  {cmd}: {s['nonzero']}/{s['runs']} nonzero exit, "
                  f"{s['with_traceback']} with a traceback: {'; '.join(s['seen'])}")  # fmt: skip
    return 0 if bad == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
