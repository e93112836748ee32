"""The live progress line of `rllib train` (hand-made Tune results, no Ray run)."""

from __future__ import annotations

import io
from types import SimpleNamespace

from rllib_asor.cli.progress import WIDTH, LineReporter

RESULT = {
    "training_iteration": 12,
    "num_env_steps_sampled_lifetime": 100_000,
    "time_total_s": 250.0,
    "env_runners": {"episode_return_mean": -12.34567},
    "race": {"success_rate": 0.3125, "curriculum_stage": 1},
    "asor": {"bonus_share": 0.04, "potential_share": 0.3, "disc_acc": 0.81, "lambda": 0.05},
}


def test_line_shows_rate_eta_and_headline_metrics_within_100_columns():
    line = LineReporter({"num_env_steps_sampled_lifetime": 400_000}).line(0, "RUNNING", RESULT)
    assert line.startswith("[0] it 12  steps 100k/400k  400/s  ETA 12m")
    for part in ("return -12.35", "success 0.31", "bonus 0.040", "disc 0.81"):
        assert part in line
    assert len(line) <= WIDTH
    assert "stage 1" in LineReporter().line(0, "RUNNING", RESULT)  # fits without steps goal/ETA
    # Optional fields that do not fit are left out whole, never cut.
    long = dict(RESULT, env_runners={"episode_return_mean": -1.23456789e12})
    line = LineReporter({"training_iteration": 10**9}).line(12345, "TERMINATED", long)
    assert len(line) <= WIDTH and line.endswith("terminated")
    assert all(
        p.split(" ")[0]
        in ("[12345]", "it", "steps", "return", "success", "stage", "bonus", "disc", "terminated")
        or p.endswith("/s")
        for p in line.split("  ")
    )


def test_line_without_optional_metrics_or_stop_has_no_eta_and_stays_short():
    bare = {"training_iteration": 3, "num_env_steps_sampled_lifetime": 512, "time_total_s": 2.0}
    line = LineReporter().line(7, "TERMINATED", bare)
    assert line == "[7] it 3  steps 512  256/s  terminated"
    no_episode_yet = dict(bare, env_runners={"episode_return_mean": float("nan")})
    assert LineReporter().line(7, "TERMINATED", no_episode_yet) == line


def test_reporter_prints_each_new_result_once_and_skips_pending():
    out = io.StringIO()
    reporter = LineReporter(every_s=0.0, out=out)
    pending = SimpleNamespace(trial_id="a", status="PENDING", last_result={})
    running = SimpleNamespace(trial_id="b", status="RUNNING", last_result=RESULT)
    assert reporter.should_report([pending, running])
    reporter.report([pending, running], done=False)
    assert not reporter.should_report([pending, running])  # nothing new
    running.last_result = dict(RESULT, training_iteration=13)
    assert reporter.should_report([pending, running])
    reporter.report([pending, running], done=False)
    lines = out.getvalue().splitlines()
    assert [line.split("  ")[0] for line in lines] == ["[1] it 12", "[1] it 13"]


def test_bonus_is_the_bonus_share_not_the_potential_share():
    line = LineReporter().line(0, "RUNNING", RESULT)
    assert "bonus 0.040" in line and "0.300" not in line


def test_line_says_when_asor_is_inert_and_stops_saying_it_once_it_works():
    out = io.StringIO()
    reporter = LineReporter(every_s=0.0, out=out)
    at_chance = {"js_estimate": 0.002, "disc_acc": 0.5, "active": 1.0, "bonus_share": 0.01}
    trial = SimpleNamespace(trial_id="t", status="RUNNING", last_result={})
    for it in range(1, 11):
        trial.last_result = dict(RESULT, training_iteration=it, asor=at_chance)
        assert reporter.should_report([trial])
        reporter.report([trial], done=False)
    lines = out.getvalue().splitlines()
    assert all("inert" not in line for line in lines[:9])  # fewer than 10 iterations: no verdict
    assert lines[9].endswith("asor inert: disc at chance") and len(lines[9]) <= 100
    trial.last_result = dict(RESULT, training_iteration=11, asor=dict(at_chance, js_estimate=0.2))
    reporter.should_report([trial])
    reporter.report([trial], done=False)
    assert "inert" not in out.getvalue().splitlines()[-1]
