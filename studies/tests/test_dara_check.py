"""studies/dara_check: the task is what its README says (the dynamics differ only above
a = 0.5, the target slips back, the source jumps) and the normalised score is the rule's."""

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


def test_the_best_target_policy_beats_random_and_scores_100(run):
    best, rand = (run.score(run.reference_policies()[k], 0) for k in ("optimal", "random"))
    assert best > rand + 20
    results = {"random/seed0": {"score": rand}, "optimal/seed0": {"score": best},
               "m/seed0": {"score": (best + rand) / 2}}  # fmt: skip
    assert run.normalised(results, "optimal/seed0", 0) == pytest.approx(100)
    assert run.normalised(results, "m/seed0", 0) == pytest.approx(50)
