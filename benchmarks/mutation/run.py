"""Mutation testing, one package at a time (docs/testing.md).

    python -m benchmarks.mutation.run                  # every package of packages.toml, in order
    python -m benchmarks.mutation.run asor glue        # some of them
    python -m benchmarks.mutation.run --report asor    # only summarise the last run

For each package: the working tree (tracked and untracked-but-not-ignored files) is copied to
build/mutation/<package>/, the package's [tool.mutmut] settings are appended to that copy's
pyproject.toml, a package's `undecorate` decorators are rebound after their functions in that
copy (mutmut skips decorated functions), and `mutmut run` is started there under `nice -n 19`
(or `--nice N`), so mutmut's `mutants/` sandbox never appears in the checkout, and a second
run reuses the first one's results for every function whose source and tests did not change.
Then the kill ratio is computed:

    killed / (mutants − equivalent)       killed includes timeouts; "no tests" counts as survived

with the equivalent mutants listed, each with its reason, in equivalent.toml. The summary goes
to stdout and to build/mutation/<package>.json. The exit status is 1 when a package is below
its threshold or a survivor is neither killed nor listed as equivalent (and --check is given).

The verdicts are also kept in benchmarks/mutation/verdicts/<package>.json (verdicts.py), written
every few minutes during a run and at its end: commit it, and a fresh checkout's run starts
from those verdicts instead of from zero (mutmut re-tests the mutants of changed functions).
"""

from __future__ import annotations

import argparse
import ast
import fnmatch
import json
import os
import shutil
import subprocess
import sys
import tomllib
from collections.abc import Callable
from pathlib import Path

from benchmarks.mutation import verdicts

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
BUILD = ROOT / "build" / "mutation"

# mutmut's CPU or wall-clock limit: a mutant that hangs, or one slowed by a busy machine (the
# wall-clock limit is short for slow tests: it is set from the tests' own durations)
TIMEOUTS = {-24, 24, 152}
KILLED = {1, 3, 36, 255} | TIMEOUTS  # failed tests, pytest internal error, timeouts
SURVIVED = {0}
NO_TESTS = {5, 33}
SKIPPED = {34}


def load_packages() -> tuple[dict, dict]:
    data = tomllib.loads((HERE / "packages.toml").read_text())
    return data.get("defaults", {}), data["package"]


def _listed(mutant: str, equivalent: dict[str, str]) -> bool:
    """Whether `mutant` is listed as equivalent (a name, or a glob over names)."""
    return mutant in equivalent or any(fnmatch.fnmatch(mutant, p) for p in equivalent)


def load_equivalent() -> dict[str, dict[str, str]]:
    path = HERE / "equivalent.toml"
    return tomllib.loads(path.read_text()) if path.exists() else {}


def _toml_list(values: list[str]) -> str:
    return "[" + ", ".join(json.dumps(v) for v in values) + "]"


def sync_tree(dest: Path) -> None:
    """Copy the working tree's tracked and untracked-not-ignored files to dest (only the
    changed ones, so mutmut's caches stay valid), and delete files no longer there."""
    out = subprocess.run(
        ["git", "ls-files", "-co", "--exclude-standard", "-z"],
        cwd=ROOT,
        check=True,
        capture_output=True,
    ).stdout.decode()
    files = {f for f in out.split("\0") if f and (ROOT / f).is_file()}
    for rel in files:
        src, dst = ROOT / rel, dest / rel
        if dst.exists() and dst.stat().st_mtime == src.stat().st_mtime:
            if dst.stat().st_size == src.stat().st_size:
                continue
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(src, dst)
    for sub in ("rllib_asor", "game_env", "tests"):
        for path in (dest / sub).rglob("*.py") if (dest / sub).exists() else ():
            if str(path.relative_to(dest)) not in files:
                path.unlink()


def undecorated(source: str, decorators: list[str]) -> str:
    """`source` with each function whose decorators are all among `decorators` (their source
    text, e.g. "torch.no_grad()") rebound after its body instead: `@d1 @d2 def f` becomes
    `def f` + `f = d1(d2(f))`, the same object under the same name. mutmut 3.8 does not mutate
    a decorated function other than a lone classmethod or staticmethod (left as they are);
    undecorated, it does."""
    tree = ast.parse(source)
    lines = source.splitlines(keepends=True)
    edits = []  # (first decorator line, last decorator line, last line of the function, binding)
    for node in ast.walk(tree):
        if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) or not node.decorator_list:
            continue
        decs = [ast.get_source_segment(source, d) for d in node.decorator_list]
        if decs in (["classmethod"], ["staticmethod"]) or not all(d in decorators for d in decs):
            continue
        bound = node.name
        for dec in reversed(decs):
            bound = f"{dec}({bound})"
        first, last = node.decorator_list[0].lineno, node.decorator_list[-1].end_lineno
        if node.end_lineno is not None and last is not None:
            edits.append((first, last, node.end_lineno, f"{node.name} = {bound}"))
    for first, last, end, binding in sorted(edits, reverse=True):  # bottom up: lines stay valid
        indent = lines[first - 1][: len(lines[first - 1]) - len(lines[first - 1].lstrip())]
        lines.insert(end, f"{indent}{binding}\n")
        del lines[first - 1 : last]
    return "".join(lines)


def undecorate_tree(dest: Path, pkg: dict) -> None:
    """Apply `undecorated` to the package's mutated files in the copy (not the checkout)."""
    decorators = list(pkg.get("undecorate", []))
    if not decorators:
        return
    for pattern in pkg["only_mutate"]:
        for path in sorted(dest.glob(pattern)):
            text = path.read_text()
            new = undecorated(text, decorators)
            if new != text:
                path.write_text(new)


def write_config(dest: Path, defaults: dict, pkg: dict) -> None:
    base = (ROOT / "pyproject.toml").read_text()
    skip = list(defaults.get("skip_lines", [])) + list(pkg.get("skip_lines", []))
    section = "\n".join(
        [
            "",
            "[tool.mutmut]",
            f"source_paths = {_toml_list(pkg['source_paths'])}",
            f"only_mutate = {_toml_list(pkg['only_mutate'])}",
            f"pytest_add_cli_args_test_selection = {_toml_list(pkg['tests'])}",
            f"pytest_add_cli_args = {_toml_list(['-p', 'no:randomly', '-q'])}",
            f"do_not_mutate_patterns = {_toml_list(skip)}",
            f"timeout_constant = {float(pkg.get('timeout_constant', defaults['timeout_constant']))}",
            "",
        ]
    )
    path = dest / "pyproject.toml"
    text = base + section
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


def run_mutmut(
    dest: Path, children: int, names: list[str], nice: int = 19, package: str = "",
    save_every_s: float = 300.0,
) -> int:  # fmt: skip
    mutmut = Path(sys.executable).with_name("mutmut")
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", PYTHONHASHSEED="0")
    cmd = ["nice", "-n", str(nice), str(mutmut), "run", "--max-children", str(children), *names]
    print(
        "+",
        " ".join(cmd[:8]),
        f"(+{len(names)} mutant names)" if names else "",
        f"(in {dest})",
        flush=True,
    )
    with subprocess.Popen(cmd, cwd=dest, env=env) as proc:
        while True:
            try:
                return proc.wait(timeout=save_every_s)
            except subprocess.TimeoutExpired:  # a session may end mid-run: keep what is done
                if package:
                    verdicts.save(package, dest)


def summarise(name: str, dest: Path, pkg: dict, equivalent: dict[str, str]) -> dict:
    counts = {"killed": 0, "survived": 0, "no_tests": 0, "skipped": 0, "other": 0, "not_checked": 0}
    survivors: list[str] = []
    unchecked: list[str] = []
    names: set[str] = set()
    for meta in sorted((dest / "mutants").rglob("*.py.meta")):
        rel = meta.relative_to(dest / "mutants").as_posix()[: -len(".meta")]
        if not any(Path(rel).match(g) or rel.startswith(g.rstrip("*")) for g in pkg["only_mutate"]):
            continue
        for key, code in json.loads(meta.read_text())["exit_code_by_key"].items():
            if pkg.get("mutants") and not any(fnmatch.fnmatch(key, p) for p in pkg["mutants"]):
                continue
            names.add(key)
            if code in KILLED:
                counts["killed"] += 1
            elif code in SKIPPED:
                counts["skipped"] += 1
            elif code is None:  # the run was stopped before this mutant
                counts["not_checked"] += 1
                unchecked.append(key)
            elif code in SURVIVED or code in NO_TESTS:
                counts["survived" if code in SURVIVED else "no_tests"] += 1
                survivors.append(key)
            else:
                counts["other"] += 1
                survivors.append(key)
    total = sum(counts.values()) - counts["skipped"] - counts["not_checked"]
    equiv = [s for s in survivors if _listed(s, equivalent)]
    open_survivors = [s for s in survivors if not _listed(s, equivalent)]
    scored = total - len(equiv)
    ratio = counts["killed"] / scored if scored else 1.0
    return {
        "package": name,
        "mutants": total,
        **counts,
        "equivalent": len(equiv),
        "kill_ratio": round(ratio, 4),
        "threshold": pkg.get("threshold", 0.8),
        "open_survivors": open_survivors,
        "not_checked_mutants": unchecked,
        "stale_equivalents": sorted(
            p for p in equivalent if not any(fnmatch.fnmatch(s, p) for s in survivors)
        ),
    }


def _set_verdicts(dest: Path, pick: Callable[[str, int | None], bool], code: int | None) -> None:
    """Set the verdict of every mutant `pick(name, verdict)` selects to `code`, in mutmut's
    own records (its next run tests exactly the mutants without a verdict)."""
    for meta in (dest / "mutants").rglob("*.py.meta"):
        data = json.loads(meta.read_text())
        codes = data["exit_code_by_key"]
        hit = [k for k, v in codes.items() if pick(k, v)]
        if hit:
            codes.update(dict.fromkeys(hit, code))
            meta.write_text(json.dumps(data))


def forget_verdicts(dest: Path, mutants: set[str]) -> None:
    """Mark these mutants untested, so that mutmut's next run tests them again and keeps every
    other verdict (naming mutants on mutmut's command line instead drops the others' verdicts)."""
    _set_verdicts(dest, lambda k, _: k in mutants, None)


def forget_timeouts(dest: Path) -> None:
    """Mark every timed-out mutant untested, so that the next run tests it again (on an idle
    machine a timeout is a hang; on a busy one it may be a slow pass)."""
    _set_verdicts(dest, lambda _, v: v in TIMEOUTS, None)


def skip_unselected(dest: Path, patterns: list[str]) -> None:
    """Mark the untested mutants outside the package's `mutants` patterns skipped, so that a
    run without names tests only the selected ones (mutmut re-tests every mutant it is given
    by name, even those with a verdict)."""
    _set_verdicts(
        dest,
        lambda k, v: v is None and not any(fnmatch.fnmatch(k, p) for p in patterns),
        next(iter(SKIPPED)),
    )


def main(argv: list[str] | None = None) -> int:
    defaults, packages = load_packages()
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("packages", nargs="*", help=f"of {', '.join(packages)} (default: all)")
    ap.add_argument("--report", action="store_true", help="only summarise the last run")
    ap.add_argument("--children", type=int, default=2, help="mutants tested at once (2)")
    ap.add_argument("--check", action="store_true", help="exit 1 below a threshold")
    ap.add_argument(
        "--nice", type=int, default=19, help="niceness of mutmut (19: only idle CPU time)"
    )
    ap.add_argument(
        "--rerun-open",
        action="store_true",
        help="test the last run's open survivors and timeouts again (after new tests, or after "
        "a run beside other work); untested mutants are always tested",
    )
    args = ap.parse_args(argv)
    names = args.packages or list(packages)
    unknown = [n for n in names if n not in packages]
    if unknown:
        ap.error(f"unknown package(s) {unknown}; known: {list(packages)}")
    equivalent = load_equivalent()
    ok = True
    summaries = []
    for name in names:
        pkg, dest = packages[name], BUILD / name
        restored = verdicts.restore(name, dest)  # a fresh checkout: start from the record
        if restored:
            print(f"{name}: {restored} verdicts restored from {verdicts.record_path(name)}")
        if not args.report:
            dest.mkdir(parents=True, exist_ok=True)
            sync_tree(dest)
            undecorate_tree(dest, pkg)
            write_config(dest, defaults, pkg)
            names = list(pkg.get("mutants", []))
            if (dest / "mutants").exists():  # a later run: keep every verdict, test the rest
                if args.rerun_open:
                    last = summarise(name, dest, pkg, equivalent.get(name, {}))
                    forget_verdicts(dest, set(last["open_survivors"]))
                    forget_timeouts(dest)
                    # mutmut re-collects which tests run which function only for new tests:
                    # a function new to the source (or newly mutated) keeps "no tests" until
                    # the stats are collected again in full (one run of the selected tests)
                    (dest / "mutants" / "mutmut-stats.json").unlink(missing_ok=True)
                if names:
                    skip_unselected(dest, names)
                    names = []
            rc = run_mutmut(dest, args.children, names, args.nice, package=name)
            if rc != 0:
                print(f"mutmut run for {name} exited {rc}", file=sys.stderr)
                ok = False
        verdicts.save(name, dest)
        summary = summarise(name, dest, pkg, equivalent.get(name, {}))
        (BUILD / f"{name}.json").write_text(json.dumps(summary, indent=2) + "\n")
        summaries.append(summary)
        below = summary["kill_ratio"] < summary["threshold"]
        ok = ok and not below
        print(
            f"{name}: {summary['killed']} killed of {summary['mutants']} mutants tested "
            f"({summary['not_checked']} not yet), "
            f"{summary['equivalent']} equivalent, {len(summary['open_survivors'])} open "
            f"survivors -> kill ratio {summary['kill_ratio']:.1%} "
            f"(threshold {summary['threshold']:.0%}{', BELOW' if below else ''})"
        )
        for s in summary["open_survivors"]:
            print(f"  survived: {s}")
        for s in summary["stale_equivalents"]:
            print(f"  listed as equivalent but not a survivor (stale entry?): {s}")
    groups: dict[str, list[dict]] = {}
    for s in summaries:
        groups.setdefault(packages[s["package"]].get("group", "others"), []).append(s)
    for group, members in sorted(groups.items()):
        killed = sum(s["killed"] for s in members)
        scored = sum(s["mutants"] - s["equivalent"] for s in members)
        print(
            f"group {group} ({', '.join(s['package'] for s in members)}): "
            f"{killed}/{scored} = {killed / max(scored, 1):.1%}"
        )
    return 0 if ok or not args.check else 1


if __name__ == "__main__":
    sys.exit(main())
