"""studies/dara_check: the task is what its README says (the dynamics differ only above
a = 0.5, the target slips back, the source jumps), and the normalised score and the verdict
on DARA against MAPLE are the rule's."""

from __future__ import annotations

import numpy as np
import pytest

from studies.tests.test_study_rules import study_script


@pytest.fixture(scope="module")
def run():
    return study_script("dara_check", "run")


def step(run, dynamics: str, a: float) -> float:
    env = run.SlipEnv(dynamics)
    env.reset(seed=0)
    x0 = env.x
    env.step(np.array([a], np.float32))
    return env.x - x0


def test_the_dynamics_agree_up_to_half_and_differ_above(run):
    for a in (-1.0, 0.2, 0.5):
        assert step(run, "original", a) == pytest.approx(a)
        assert step(run, "boost", a) == pytest.approx(a)
    assert step(run, "original", 0.8) == pytest.approx(-1.0)  # the target slips back
    assert step(run, "boost", 0.8) == pytest.approx(1.6)  # the source jumps
    with pytest.raises(ValueError, match=r"dynamics='wind' is invalid: allowed original \| boost"):
        run.SlipEnv("wind")


def test_the_best_target_policy_beats_random_and_the_rules_verdicts():
    run, summary = study_script("dara_check", "run"), study_script("dara_check", "summarise")
    best, rand = (run.score(run.reference_policies()[k], 0) for k in ("optimal", "random"))
    assert best > rand + 20
    assert summary.normalised(best, rand, best) == pytest.approx(100)
    assert summary.normalised((best + rand) / 2, rand, best) == pytest.approx(50)
    assert summary.dara_verdict([12.0, 11.0, 9.0]) == "DARA better"  # mean ≥ 10, all > 0
    assert summary.dara_verdict([30.0, 30.0, -1.0]) == "no clear difference at this budget"
    assert summary.dara_verdict([-10.0, -10.0, -10.0]) == "DARA worse"
    assert summary.dara_verdict([0.0, 0.0, 0.0]) == "no clear difference at this budget"


def test_the_confirmatory_bar_needs_every_seed_above_never_moving():
    summary = study_script("dara_check", "summarise")
    first, confirmatory, coverage = summary.RULES
    assert coverage.maple == "maple+cover" and coverage.above_still
    still = {"3": 50.0, "4": 50.0, "5": 50.0}
    assert confirmatory.learns({"3": 80.0, "4": 75.0, "5": 70.0}, still)
    assert not confirmatory.learns({"3": 100.0, "4": 100.0, "5": 49.0}, still)  # mean 83, one below
    assert not confirmatory.learns({"3": 69.0, "4": 70.0, "5": 70.0}, still)  # mean under 70
    assert first.learns({"0": 50.0, "1": 50.0, "2": 50.0}, {})  # the first rule: mean ≥ 50 only
