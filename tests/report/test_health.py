"""`asor_health`: an inert ASOR is named with its likely cause, a working one is not."""

from __future__ import annotations

import pytest

from rllib_asor.report.health import WINDOW, asor_health, group_health, health_of_rows

WORKING = {"js_estimate": 0.2, "disc_acc": 0.8, "active": 1.0, "bonus_share": 0.01,
           "critic_ev": 0.6, "archive_states": 4096.0}  # fmt: skip


def rows(**change: float) -> list[dict[str, float]]:
    return [dict(WORKING, **change) for _ in range(WINDOW)]


def test_a_working_asor_and_a_short_history_say_nothing() -> None:
    assert asor_health(rows()) is None
    assert asor_health(rows(js_estimate=0.001)[1:]) is None  # 9 iterations: no verdict yet
    robust = rows(js_estimate=0.03, bonus_share=0.005)  # the robust preset's gentle signal
    assert asor_health(robust) is None


@pytest.mark.parametrize(
    ("change", "short", "words"),
    [
        ({"js_estimate": 0.002, "critic_ev": 0.0007}, "disc at chance", "explained variance"),
        ({"active": 0.0, "archive_states": 0.0}, "archive empty", "no episode ended"),
        ({"active": 0.0, "critic_ev": -0.3}, "critic not ready", "lambda_warmup"),
        ({"bonus_share": 0.0004}, "bonus ~0", "raise lambda_"),
    ],
)
def test_each_inert_case_names_its_cause_and_advice(change, short, words) -> None:
    found = asor_health(rows(**change))
    assert found is not None and found.short == f"asor inert: {short}"
    assert words in found.line and "try: " in found.line and "\n" not in found.line


def test_one_good_iteration_in_the_window_is_not_inert() -> None:
    history = rows(js_estimate=0.002)
    history[-4] = dict(WORKING)
    assert asor_health(history) is None


def test_nan_or_missing_metrics_never_raise_a_false_alarm() -> None:
    assert asor_health(rows(js_estimate=float("nan"))) is None
    sac = [{k: v for k, v in r.items() if k not in ("critic_ev", "archive_states")} for r in rows()]
    assert asor_health(sac) is None


def test_flat_nested_and_multi_policy_rows() -> None:
    flat = [{f"asor/{k}": v for k, v in r.items()} for r in rows(js_estimate=0.001)]
    assert health_of_rows(flat).short == "asor inert: disc at chance"
    nested = [{"asor": {"p0": WORKING, "p1": dict(WORKING, bonus_share=0.0)}}] * WINDOW
    assert health_of_rows(nested).short == "asor inert (p1): bonus ~0"
    line = group_health("PPO+ASOR", [flat, [{f"asor/{k}": v for k, v in WORKING.items()}] * 10])
    assert line.startswith("PPO+ASOR: asor inert: disc at chance in 1/2 trial(s)")
    assert group_health("PPO", [[{"env_runners/episode_return_mean": 1.0}] * 12]) is None
