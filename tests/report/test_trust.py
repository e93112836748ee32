"""Per-dynamics rows carry their pair and episode counts and
are decided only after a Holm adjustment (the plot stars the same rows); no verdict where an
arm never trained, ASOR never ran or the runs are smoke runs; a folder without evaluations does
not switch every score to training returns; `differs in:` hides bookkeeping and never cuts a
name."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest
from statsmodels.stats.multitest import multipletests

from rllib_asor.report import paired, plots
from rllib_asor.report.compare import compare, render_text
from rllib_asor.report.results import SMOKE_KEY
from tests.report.helpers import write_trial

ENV = "MyDrone-v0"
DYN = "rllib_asor.evaluation.dynamics.DynamicsReturnsCallback"
ASOR_CB = "rllib_asor.rllib.callbacks.AsorMetricsCallback"
TRAINED = {
    "learners/__all_modules__/num_env_steps_trained_lifetime": 4000,
    "learners/default_policy/num_module_steps_trained_lifetime": 4000,
    "num_training_step_calls_per_iteration": 1,
    "timers/training_step": 0.5,
}
"""What RLlib's result rows hold once a Learner updated the policy (a real PPO run's keys)."""
BEFORE_LEARNING = {"num_training_step_calls_per_iteration": 1, "timers/training_step": 0.5}
"""What a real SAC run reports before `num_steps_sampled_before_learning_starts`: no learner
metrics at all (`rllib train file tuned_examples/mujoco/sac-asor-hopper.yaml --test`)."""
ASOR_RAN = {"asor/js_estimate": 0.3, "asor/active": 1.0, "asor/bonus_share": 0.01}


def base_params(seed: int, **more: Any) -> dict[str, Any]:
    return {"env": ENV, "seed": seed, "rllib_asor_run": "PPO", **more}


def asor_params(seed: int, **more: Any) -> dict[str, Any]:
    return base_params(seed, asor={"mode": "asor"}, **more)


# ------------------------------------------------------------------ per dynamics

SEEDS = 8
EFFECTS = {  # dynamics id -> the paired difference per seed (treatment - baseline)
    "0": [10.0, 11.0, 12.0, 13.0, 14.0, 15.0, 16.0, 17.0],  # all positive: raw p 2/256
    "1": [5.0, 6.0, 7.0, 8.0, 9.0, 10.0, -6.5, 11.0],  # raw p < 0.05, CI > 0, Holm p > 0.05
    "2": [1.0, -1.0, 2.0, -2.0, 3.0, -3.0, 0.5, -0.5],  # nothing
    "3": [2.0, -2.0, 1.0, -1.0, 3.0, -3.0, 0.5, 4.0],  # one episode per trial: flagged
}
EPISODES = {"0": 3, "1": 3, "2": 3, "3": 1}


def per_dynamics_folder(root: Path) -> Path:
    """8 paired seeds scored by evaluation.json: 4 dynamics in both arms, dynamics 4 in the
    treatment's evaluation only, dynamics 7 in training only."""
    for s in range(SEEDS):
        for arm, params in (("base", base_params(s)), ("asor", asor_params(s))):
            returns: list[float] = []
            ids: list[Any] = []
            for did, n in EPISODES.items():
                value = 100.0 + 7 * s + (EFFECTS[did][s] if arm == "asor" else 0.0)
                returns += [value] * n
                ids += [int(did)] * n
            if arm == "asor":
                returns.append(50.0)
                ids.append(4)
            ev = {"seed": 1000000, "returns": returns, "dynamics_ids": ids}
            extra = {**TRAINED, **(ASOR_RAN if arm == "asor" else {}),
                     "env_runners/dynamics/7/episode_return_mean": 3.0}  # fmt: skip
            write_trial(root, f"{arm}_{s}", params, [1.0], evaluation=ev, extra=extra)
    return root


def test_per_dynamics_rows_carry_pairs_and_episode_counts(tmp_path: Path) -> None:
    comp = compare([per_dynamics_folder(tmp_path)])
    rows = {r.dynamics: r for r in comp.results if r.dynamics is not None}
    assert sorted(rows) == ["0", "1", "2", "3"]
    for did, r in rows.items():
        n = EPISODES[did]
        assert r.pairs == SEEDS
        assert (r.baseline_episodes, r.treatment_episodes) == (SEEDS * n, SEEDS * n)
        assert (r.baseline_min_episodes, r.treatment_min_episodes) == (n, n)
        assert r.few_episodes is (n < 2)
    text = render_text(comp)
    assert "| 3 | PPO+ASOR | 8 | 8 / 8 | 1 / 1 (few) |" in text
    assert "| 0 | PPO+ASOR | 8 | 24 / 24 | 3 / 3 |" in text


def test_per_dynamics_p_values_are_holm_adjusted_and_only_those_rows_decided(
    tmp_path: Path,
) -> None:
    comp = compare([per_dynamics_folder(tmp_path)])
    dyn = [r for r in comp.results if r.dynamics is not None]
    raw = [r.p_value for r in dyn]
    expected = multipletests(raw, method="holm")[1]  # an independent implementation
    assert [r.p_adjusted for r in dyn] == pytest.approx(list(expected))
    one = next(r for r in dyn if r.dynamics == "1")
    assert one.p_value < 0.05 and one.ci_low > 0  # decided before the adjustment ...
    assert one.p_adjusted >= 0.05 and not paired.decided(one)  # ... exploratory after it
    assert one.verdict.startswith("exploratory")
    assert [r.dynamics for r in dyn if paired.decided(r)] == ["0"]
    text = render_text(comp)
    assert "Holm" in text
    row0 = next(line for line in text.splitlines() if line.startswith("| 0 | PPO+ASOR"))
    row1 = next(line for line in text.splitlines() if line.startswith("| 1 | PPO+ASOR"))
    assert row0.endswith("| decided: better |") and row1.endswith("| exploratory |")


def test_episode_counts_of_evaluation_during_training(tmp_path: Path) -> None:
    # DynamicsReturnsCallback's num_episodes is per iteration (a real run: 4, 1, 1, 4 episodes
    # of dynamics 5, 4, 2, 3 in one iteration, 4, 2, 5, 2 in the next)
    for s in range(3):
        for arm, params, shift in (("b", base_params(s), 0.0), ("a", asor_params(s), 1.0)):
            counts = {"evaluation/env_runners/dynamics/0/num_episodes": 2 + s}
            if s:  # dynamics 1's count is recorded for seeds 1 and 2 only
                counts["evaluation/env_runners/dynamics/1/num_episodes"] = 1
            write_trial(tmp_path, f"{arm}{s}", params, [1.0, 1.0], eval_returns=[5.0, 5.0 + s],
                        eval_dynamics={"0": [1.0, 2.0 + shift], "1": [3.0, 3.0 + shift]},
                        extra={**TRAINED, **ASOR_RAN, **counts})  # fmt: skip
    for last_n, total, fewest in ((1, 9, 2), (2, 18, 4)):
        comp = compare([tmp_path], last_n=last_n)
        assert comp.sources[ENV].kind == "evaluation"
        d0, d1 = (r for r in comp.results if r.dynamics is not None)
        assert (d0.baseline_episodes, d0.treatment_min_episodes) == (total, fewest)
        assert d1.baseline_episodes is None and d1.baseline_min_episodes is None
    assert "| 1 | PPO+ASOR | 3 | n/a | n/a |" in render_text(comp)


def test_dynamics_plot_stars_exactly_the_rows_the_table_decides(tmp_path: Path) -> None:
    comp = compare([per_dynamics_folder(tmp_path)])
    dyn = [r for r in comp.results if r.dynamics is not None]
    labels, title = plots.plot_dynamics(dyn, tmp_path / "dyn.png")
    assert [r.dynamics for r, label in zip(dyn, labels, strict=True) if label.endswith("*")] == [
        r.dynamics for r in dyn if paired.decided(r)
    ]
    assert "Holm" in title and "*" in title
    # 3 pairs whose interval excludes 0 (p 0.25): starred "CI excludes 0" before, never now
    few = tmp_path / "few"
    for s in range(3):
        ev = {"seed": 1, "returns": [10.0 * s, 5.0], "dynamics_ids": [0, 1]}
        tev = {"seed": 1, "returns": [10.0 * s + 3 + s, 5.0], "dynamics_ids": [0, 1]}
        write_trial(few, f"b{s}", base_params(s), [1.0], evaluation=ev, extra=TRAINED)
        write_trial(few, f"a{s}", asor_params(s), [1.0], evaluation=tev,
                    extra={**TRAINED, **ASOR_RAN})  # fmt: skip
    dyn3 = [r for r in compare([few]).results if r.dynamics is not None]
    assert dyn3[0].ci_low > 0
    labels, _ = plots.plot_dynamics(dyn3, tmp_path / "dyn3.png")
    assert not any(label.endswith("*") for label in labels)


def test_dynamics_without_evaluation_episodes_are_listed(tmp_path: Path) -> None:
    comp = compare([per_dynamics_folder(tmp_path)])
    (main,) = [r for r in comp.results if r.dynamics is None]
    assert main.dynamics_one_arm == {"PPO+ASOR": ["4"]}
    assert main.dynamics_training_only == ["7"]
    text = render_text(comp)
    assert "dynamics without evaluation episodes: 4 (evaluated in PPO+ASOR only)" in text
    assert "7 (in training, in no evaluation)" in text


# ------------------------------------------------------------------ no verdict


def ab_pairs(root: Path, seeds: int, base_extra: dict, treat_extra: dict, **params: Any) -> Path:
    for s in range(seeds):
        write_trial(root, f"b{s}", base_params(s, **params), [10.0 + s], extra=base_extra)
        write_trial(root, f"a{s}", asor_params(s, **params), [30.0 + s], extra=treat_extra)
    return root


def test_no_verdict_when_an_arm_never_updated_its_policy(tmp_path: Path) -> None:
    ab_pairs(tmp_path / "none", 6, BEFORE_LEARNING, BEFORE_LEARNING)
    (res,) = compare([tmp_path / "none"]).results
    assert res.verdict == (
        "no verdict: PPO never updated its policy (0 env steps trained in 6 of 6 trials); "
        "PPO+ASOR never updated its policy (0 env steps trained in 6 of 6 trials)"
    )
    assert not paired.decided(res) and res.pairs_needed is None
    one = tmp_path / "one"
    ab_pairs(one, 6, TRAINED, {**TRAINED, **ASOR_RAN})
    write_trial(one, "a6", asor_params(6), [36.0], extra=BEFORE_LEARNING)
    write_trial(one, "b6", base_params(6), [16.0], extra=TRAINED)
    (res,) = compare([one]).results
    assert res.verdict == (
        "no verdict: PPO+ASOR never updated its policy (0 env steps trained in 1 of 7 trials)"
    )


def test_no_verdict_when_asor_never_ran(tmp_path: Path) -> None:
    ab_pairs(tmp_path / "inert", 6, TRAINED, TRAINED)
    (res,) = compare([tmp_path / "inert"]).results
    assert (
        res.verdict == "no verdict: ASOR never ran in PPO+ASOR (no asor/ metrics in 6 of 6 trials)"
    )
    assert "no verdict: ASOR never ran" in render_text(compare([tmp_path / "inert"]))
    ab_pairs(tmp_path / "ran", 6, TRAINED, {**TRAINED, **ASOR_RAN})
    (res,) = compare([tmp_path / "ran"]).results
    assert res.verdict.startswith("treatment better") and paired.decided(res)


def test_smoke_runs_get_no_verdict_and_stay_apart_from_real_runs(tmp_path: Path) -> None:
    smoke = {SMOKE_KEY: True}
    ab_pairs(tmp_path / "smoke", 2, TRAINED, {**TRAINED, **ASOR_RAN}, **smoke)
    comp = compare([tmp_path / "smoke"])
    (res,) = comp.results
    assert res.smoke and res.verdict == "smoke run (--test): no verdict"
    text = render_text(comp)
    assert "smoke run" in text.splitlines()[0] and "PPO+ASOR vs PPO" in text
    assert SMOKE_KEY not in text
    ab_pairs(tmp_path / "real", 6, TRAINED, {**TRAINED, **ASOR_RAN})
    comp = compare([tmp_path / "real", tmp_path / "smoke"])
    by_smoke = {r.smoke: r for r in comp.results}
    assert by_smoke[False].pairs == 6 and by_smoke[False].verdict.startswith("treatment better")
    assert by_smoke[True].pairs == 2 and by_smoke[True].verdict == "smoke run (--test): no verdict"
    assert any("smoke" in n and "apart" in n for n in comp.notes)


def test_a_folder_without_evaluations_keeps_the_others_on_evaluation_scores(
    tmp_path: Path,
) -> None:
    for s in range(4):  # folder A: evaluated (evaluation returns 30 + s and 32 + s)
        write_trial(tmp_path / "A", f"b{s}", base_params(s), [500.0], eval_returns=[30.0 + s],
                    extra=TRAINED)  # fmt: skip
        write_trial(tmp_path / "A", f"a{s}", asor_params(s), [0.0], eval_returns=[32.0 + s],
                    extra={**TRAINED, **ASOR_RAN})  # fmt: skip
    for s in range(4, 7):  # folder B: training returns only
        write_trial(tmp_path / "B", f"b{s}", base_params(s), [500.0], extra=TRAINED)
        write_trial(tmp_path / "B", f"a{s}", asor_params(s), [0.0], extra={**TRAINED, **ASOR_RAN})
    comp = compare([tmp_path / "A", tmp_path / "B"])
    assert comp.sources[ENV].kind == "evaluation"
    (res,) = comp.results
    assert res.pairs == 4 and res.diff_mean == pytest.approx(2.0)  # not -500 (training)
    (note,) = [n for n in comp.notes if "left out" in n]
    assert "6 trial(s)" in note and all(f"{a}{s}" in note for a in "ab" for s in range(4, 7))


# ------------------------------------------------------------------ one account


def test_differs_in_hides_bookkeeping_and_says_only_asor(tmp_path: Path) -> None:
    for s in range(3):
        base = base_params(
            s, rllib_asor_arm="PPO", callbacks=[f"<class '{DYN}'>"], **{SMOKE_KEY: False}
        )
        treat = {**base, "rllib_asor_arm": "PPO+ASOR", "asor": {"mode": "asor", "preset": "robust"},
                 "callbacks": [f"<class '{DYN}'>", f"<class '{ASOR_CB}'>"]}  # fmt: skip
        write_trial(tmp_path, f"b{s}", base, [1.0 + s], extra=TRAINED)
        write_trial(tmp_path, f"a{s}", treat, [2.0 + s], extra={**TRAINED, **ASOR_RAN})
    comp = compare([tmp_path])
    (res,) = comp.results
    assert res.differs_in == ["asor.mode", "asor.preset"]
    text = render_text(comp)
    assert "PPO+ASOR vs PPO (the arms differ only in ASOR): " in text
    for hidden in ("rllib_asor_arm", "rllib_asor_run", SMOKE_KEY, "callbacks"):
        assert hidden not in text


def test_other_differences_are_named_besides_asor_and_never_cut_mid_word(tmp_path: Path) -> None:
    long_cb = "my_package.callbacks.MyVeryLongCustomCallbackNameThatGoesOn"
    for s in range(3):
        base = base_params(s, rllib_asor_arm="PPO", callbacks=[f"<class '{DYN}'>"])
        treat = {**base, "rllib_asor_arm": "PPO+ASOR", "asor": {"mode": "asor"},
                 "callbacks": [f"<class '{DYN}'>", f"<class '{long_cb}'>"]}  # fmt: skip
        other = {**base, "rllib_asor_arm": None, "note": "a rather long free text setting " * 3}
        write_trial(tmp_path, f"b{s}", base, [1.0 + s], extra=TRAINED)
        write_trial(tmp_path, f"a{s}", treat, [2.0 + s], extra={**TRAINED, **ASOR_RAN})
        write_trial(tmp_path, f"o{s}", other, [2.0 + s], extra=TRAINED)
    comp = compare([tmp_path], baseline="PPO")
    text = render_text(comp)
    assert "PPO+ASOR vs PPO (besides ASOR, the arms differ in: callbacks)" in text
    assert "vs PPO (the arms differ in: note)" in text
    words = set(re.findall(r"\w+", f"{long_cb} {other['note']} missing note"))
    shown = [g.label.split(" (", 1)[1] for g in comp.groups if " (" in g.label]
    shown += [v for g in comp.groups for k, v in g.settings.items() if k in ("note", "callbacks")]
    assert any("MyVeryLongCustomCallbackNameThatGoesOn" in v for v in shown)
    assert any(v.startswith("note=a rather long") and v.endswith("…)") for v in shown)
    for value in shown:
        for word in re.findall(r"\w+", value):
            assert word in words, (word, value)  # whole words only, never a cut one


def test_metrics_only_callbacks_cover_what_with_asor_and_rllib_ab_add() -> None:
    from rllib_asor.evaluation.dynamics import DynamicsReturnsCallback
    from rllib_asor.report.grouping import METRICS_ONLY_CALLBACKS
    from rllib_asor.rllib.wiring import METRICS_CALLBACKS

    for cls in (*METRICS_CALLBACKS, DynamicsReturnsCallback):
        assert f"{cls.__module__}.{cls.__qualname__}" in METRICS_ONLY_CALLBACKS
