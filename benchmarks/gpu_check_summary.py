"""One table for `scripts/gpu_check.sh`: the gpu tests' counts, the scaling figures, the targets.

    python -m benchmarks.gpu_check_summary benchmarks/out/gpu_check

Reads OUT/gpu_tests.xml (pytest's junit report), OUT/e2e/scaling.json (sampling and end to
end), OUT/overlap/scaling.json (end to end with overlapped sampling), OUT/envs32/scaling.json
(sampling with 32 envs per runner), OUT/learner/scaling.json (the Learner alone),
OUT/compile/scaling.json (the Learner alone, its update compiled; shown beside the one not
compiled, not judged) and
OUT/split/scaling.json (where an iteration's time goes, and the weight sync), all from
`benchmarks.scaling` at minibatch 2,048; a missing file is a row or a line that says so. The
targets are those for a 16-core node with one GPU: at the most runners (14) PPO+ASOR
end to end ≥ 15,000 env steps/s and PPO ≥ 16,000, PPO+ASOR ÷ PPO ≥ 0.9, 14 ÷ 1 runners ≥ 10×;
sampling only ≥ 3,000 (one runner) and ≥ 30,000 (14); the GPU Learner alone ≥ 10,000. On a CPU
they are shown, not judged.
"""

from __future__ import annotations

import json
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from benchmarks.scaling import LABELS


def test_counts(xml: Path) -> str:
    """'passed P, failed F, skipped S' from a junit report, or why there is none."""
    if not xml.exists():
        return "no report (pytest missing, or it was stopped by the time limit)"
    root = ET.parse(xml).getroot()
    suite = root if root.tag == "testsuite" else root.find("testsuite")
    if suite is None:
        return "unreadable report"
    n = {k: int(suite.get(k, 0)) for k in ("tests", "failures", "errors", "skipped")}
    passed = n["tests"] - n["failures"] - n["errors"] - n["skipped"]
    return f"passed {passed}, failed {n['failures'] + n['errors']}, skipped {n['skipped']}"


def load(path: Path) -> dict[str, Any] | None:
    return json.loads(path.read_text()) if path.exists() else None


def rate(res: dict[str, Any] | None, algo: str, runners: int, part: str) -> float | None:
    for row in (res or {}).get("rows", []):
        if row["algo"] == algo and row["runners"] == runners and isinstance(row.get(part), float):
            return row[part]
    return None


def fmt(x: float | None, digits: int = 0) -> str:
    return "—" if x is None else f"{x:,.{digits}f}"


def targets(
    e2e: dict[str, Any] | None,
    learner: dict[str, Any] | None,
    overlap: dict[str, Any] | None = None,
    envs32: dict[str, Any] | None = None,
) -> list[list[str]]:
    """Rows (check, measured, target, verdict) of the GPU node's targets (a 16-core
    node with one GPU, 14 runners); with `overlap`, the end-to-end targets again for
    overlapped sampling; with `envs32`, the sampling targets again at 32 envs per runner."""
    counts = sorted({r["runners"] for r in (e2e or {}).get("rows", [])})
    cuda = (e2e or learner or overlap or envs32 or {}).get("settings", {}).get("device") == "cuda"
    rows = []
    if counts:
        lo, hi = counts[0], counts[-1]
        asor, ppo = rate(e2e, "asor", hi, "e2e"), rate(e2e, "ppo", hi, "e2e")
        one = rate(e2e, "asor", lo, "e2e")
        ratio = asor / one if one and asor else None
        rel = asor / ppo if asor and ppo else None
        sample_one, sample_many = rate(e2e, "ppo", lo, "sample"), rate(e2e, "ppo", hi, "sample")
        learners = [
            row["learner"]
            for res in (e2e, learner)
            for row in (res or {}).get("rows", [])
            if isinstance(row.get("learner"), float)
        ]
        best = max(learners, default=None)
        at_one = lo == 1  # the targets against one runner: another base is shown, not judged
        rows = [
            [f"PPO+ASOR end to end, {hi} runners (env steps/s)", fmt(asor), "≥ 15,000", asor,
             15_000.0],
            [f"PPO end to end, {hi} runners (env steps/s)", fmt(ppo), "≥ 16,000", ppo, 16_000.0],
            [f"PPO+ASOR ÷ PPO end to end, {hi} runners", fmt(rel, 2), "≥ 0.9", rel, 0.9],
        ]  # fmt: skip
        if lo != hi:  # the fewest runners against the most (not shown for one runner count)
            rows += [
                [f"PPO+ASOR end to end, {hi} ÷ {lo} runners", fmt(ratio, 2), "≥ 10 (÷ 1 runner)",
                 ratio if at_one else None, 10.0],
                [f"sampling only, {lo} runner(s) (env steps/s)", fmt(sample_one),
                 "≥ 3,000 (1 runner)", sample_one if at_one else None, 3_000.0],
            ]  # fmt: skip
        rows += [
            [f"sampling only, {hi} runners (env steps/s)", fmt(sample_many), "≥ 30,000",
             sample_many, 30_000.0],
            ["Learner alone, best (env steps/s)", fmt(best), "≥ 10,000", best, 10_000.0],
        ]  # fmt: skip
    over = sorted({r["runners"] for r in (overlap or {}).get("rows", [])})
    if over:
        n = over[-1]
        ao, po = rate(overlap, "asor_overlap", n, "e2e"), rate(overlap, "ppo_overlap", n, "e2e")
        rel = ao / po if ao and po else None
        rows += [
            [f"PPO+ASOR overlapped end to end, {n} runners (env steps/s)", fmt(ao), "≥ 15,000",
             ao, 15_000.0],
            [f"PPO overlapped end to end, {n} runners (env steps/s)", fmt(po), "≥ 16,000", po,
             16_000.0],
            [f"PPO+ASOR ÷ PPO overlapped, {n} runners", fmt(rel, 2), "≥ 0.9", rel, 0.9],
        ]  # fmt: skip
    for n in sorted({r["runners"] for r in (envs32 or {}).get("rows", [])}):
        value, bar = rate(envs32, "ppo", n, "sample"), 3_000.0 if n == 1 else 30_000.0
        if n in (1, 14):  # the targets' runner counts
            rows.append([f"sampling only, 32 envs per runner, {n} runner(s) (env steps/s)",
                         fmt(value), f"≥ {bar:,.0f}", value, bar])  # fmt: skip
    out = []
    for check, shown, target, value, bar in rows:
        if not cuda:
            verdict = "not judged (CPU)"
        elif value is None:
            verdict = "not measured"
        else:
            verdict = "met" if value >= bar else "NOT met"
        out.append([check, shown, target, verdict])
    return out


def compile_rows(learner: dict[str, Any] | None, compiled: dict[str, Any] | None) -> list[str]:
    """Per algorithm: the compiled Learner ÷ the one not compiled, at the same runners and
    minibatch, and the compiled one's first (untimed) pass: shown, not judged."""
    if not compiled:
        return []
    s = compiled.get("settings", {})
    backend = s.get("compile_backend")
    how = f"{backend}, {s.get('torch_compile')}" if backend == "inductor" else backend
    lines = []
    for row in compiled.get("rows", []):
        algo, n = row["algo"], row["runners"]
        fast, slow = row.get("learner"), rate(learner, algo, n, "learner")
        if not isinstance(fast, float):
            continue
        ratio = f"{fast / slow:.2f}× ({fmt(fast)} ÷ {fmt(slow)})" if slow else f"{fmt(fast)}"
        lines.append(
            f"| Learner alone, compiled ({how}) ÷ not compiled, {LABELS[algo]}, {n} runner(s) "
            f"| {ratio}; first pass {row.get('learner_warmup_s', 0.0):.0f} s | shown | |"
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    out = Path((argv if argv is not None else sys.argv[1:])[0])
    e2e, learner = load(out / "e2e" / "scaling.json"), load(out / "learner" / "scaling.json")
    overlap, envs32 = load(out / "overlap" / "scaling.json"), load(out / "envs32" / "scaling.json")
    compiled = load(out / "compile" / "scaling.json")
    lines = ["", "| check | measured | target | verdict |", "|---|---|---|---|"]
    lines.append(
        f"| gpu tests (`pytest -m gpu`) | {test_counts(out / 'gpu_tests.xml')} | all pass | |"
    )
    parts = (
        ("sampling and end to end", e2e),
        ("overlapped", overlap),
        ("sampling, 32 envs per runner", envs32),
        ("Learner alone", learner),
        ("Learner alone, compiled", compiled),
    )
    for name, res in parts:
        if res is None:
            lines.append(f"| scaling benchmark, {name} | no result (see its log) | | |")
            continue
        device = {r.get("learner_device") for r in res["rows"]} - {None}
        lines.append(
            f"| scaling benchmark, {name} | {res['machine']}, Learner on "
            f"{', '.join(sorted(device)) or '—'}, {res['wall_s']:.0f} s | | |"
        )
        for row in res["rows"]:
            parts = [
                f"{p} {fmt(row.get(p))}"
                for p in ("e2e", "sample", "learner")
                if row.get(p) is not None
            ]
            if parts:
                lines.append(
                    f"| {LABELS[row['algo']]}, {row['runners']} runner(s) (env steps/s) "
                    f"| {'; '.join(parts)} | | |"
                )
        for note in res.get("notes", []):
            lines.append(f"| note | {note} | | |")
        if res.get("finished") is False:
            lines.append(
                f"| note | {name}: stopped by its time limit; what it measured is above | | |"
            )
    for check, shown, target, verdict in targets(e2e, learner, overlap, envs32):
        lines.append(f"| {check} | {shown} | {target} | {verdict} |")
    lines += compile_rows(learner, compiled)
    split = load(out / "split" / "scaling.json")
    if split is None:
        lines.append("\nsplit of an iteration: no result (see split.log)")
    else:
        from benchmarks.scaling import split_table, sync_table

        for part in split.get("split", []):
            lines.append(
                f"\nwhere an iteration's time goes, {part['runners']} runners ({split['machine']}):"
            )
            lines.append(split_table(part))
        if "sync" in split:
            lines.append(sync_table(split["sync"]))
    runner = load(out / "runner" / "runner_profile.json")
    if runner is None or "split" not in runner:
        lines.append("\none runner's split: no result (see runner.log)")
    else:
        from benchmarks.runner_profile import split_table as runner_table

        lines.append(f"\nwhere one env runner's time goes ({runner.get('cpus')} CPUs, no Ray):")
        lines.append(runner_table(runner["split"]))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
