"""studies.lib.paired_verdict: an arm is judged only once it and the baseline have every
planned seed, by the rule's margin; a study may read its baseline from another study."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from studies.lib import paired_verdict


def write_runs(study: Path, method: str, values: dict[int, float]) -> None:
    (study / "runs").mkdir(parents=True, exist_ok=True)
    for seed, v in values.items():
        run = {"method": method, "seed": seed, "train_wall_s": 10.0 + seed, "score": v}
        (study / "runs" / f"{method}-{seed}.json").write_text(json.dumps(run))


def test_verdict_bounds() -> None:
    assert paired_verdict.verdict(-0.05, 0.2, -0.1, 20) == "as good"
    assert paired_verdict.verdict(-0.3, -0.01, -0.1, 20) == "worse"
    assert paired_verdict.verdict(-0.2, 0.1, -0.1, 20) == "not decided at 20 pairs"


def test_arms_are_judged_only_with_every_seed_and_against_another_studys_baseline(
    tmp_path: Path,
) -> None:
    base, mine = tmp_path / "base_study", tmp_path / "my_study"
    seeds = range(6)
    write_runs(base, "today", {s: 0.5 + 0.05 * s for s in seeds})
    write_runs(mine, "close", {s: 0.5 + 0.05 * s - 0.01 for s in seeds})
    write_runs(mine, "bad", {s: 0.1 for s in seeds})
    write_runs(mine, "half", {s: 0.9 for s in range(3)})
    study = paired_verdict.PairedStudy(
        arms=("close", "bad", "half"), also=("base_study",), metric="score", seeds=seeds
    )
    res = study.summarise(mine / "runs")
    arms = res["arms"]
    assert arms["close"]["verdict"] == "as good"
    assert arms["close"]["paired"]["diff_mean"] == pytest.approx(-0.01, abs=1e-9)
    assert arms["bad"]["verdict"] == "worse"
    assert arms["half"]["verdict"].startswith("not yet: half 3 of 6, today 6 of 6 runs")
    assert "paired" not in arms["half"]
    assert res["methods"]["today"]["runs"] == 6 and res["methods"]["bad"]["train_wall_s"] == 12.5
    md = study.table(res)
    assert "Verdict for bad (README.md's rule): **worse**" in md
    assert "| close | 6 | -0.010 |" in md and "| half |" not in md.split("arm − today")[1]


def test_a_missing_baseline_is_named_in_the_wait(tmp_path: Path) -> None:
    write_runs(tmp_path / "study", "arm", {s: 0.5 for s in range(4)})
    study = paired_verdict.PairedStudy(
        arms=("arm",), baseline="base", metric="score", seeds=range(4)
    )
    res = study.summarise(tmp_path / "study" / "runs")
    assert res["arms"]["arm"]["verdict"].startswith("not yet: arm 4 of 4, base 0 of 4 runs")
