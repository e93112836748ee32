"""`rllib compare` on hand-written result folders with a known effect: the interval covers the
truth, groups are never mixed, trials are paired by seed, the JSON has its keys."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np
import pytest

from rllib_asor.cli import compare as cli
from rllib_asor.report.compare import compare, render_text
from rllib_asor.report.paired import paired_difference, pairs_needed
from tests.report.helpers import write_trial

JSON_KEYS = {"baseline", "treatment", "metric", "pairs", "baseline_mean", "treatment_mean",
             "diff_mean", "ci_low", "ci_high", "p_value"}  # fmt: skip
ENV = "MyCartPole-v0"


def ab_folder(root: Path, effect: float, seeds: int = 12, rng_seed: int = 0) -> Path:
    """PPO and PPO+ASOR trials whose final training return is seed luck (sd 30) plus, for
    ASOR, `effect` and a little noise (sd 2): the paired difference's mean is `effect`."""
    rng = np.random.default_rng(rng_seed)
    luck = rng.normal(0, 30, seeds)
    noise = rng.normal(0, 2, seeds)
    noise -= noise.mean()  # the sample's mean difference is exactly `effect`
    for s in range(seeds):
        base = {"env": ENV, "seed": s, "lr": 0.001, "rllib_asor_run": "PPO"}
        write_trial(root / "exp", f"PPO_{s}_{rng.integers(1e6)}", base, [0.0, 100 + luck[s]])
        treat = {**base, "asor": {"mode": "asor", "lambda_": 0.1}}
        write_trial(
            root / "exp",
            f"AsorPPO_{s}_{rng.integers(1e6)}",
            treat,
            [0.0, 100 + luck[s] + effect + noise[s]],
        )
    return root


@pytest.mark.parametrize("effect", [0.0, 10.0])
def test_interval_covers_the_known_effect(tmp_path: Path, effect: float) -> None:
    comp = compare([ab_folder(tmp_path, effect)])
    (res,) = comp.results
    assert (res.baseline, res.treatment, res.pairs) == ("PPO", "PPO+ASOR", 12)
    assert res.diff_mean == pytest.approx(effect)
    assert res.ci_low <= effect <= res.ci_high
    assert res.ci_high - res.ci_low < 5  # pairing removed the seed luck (sd 30)
    if effect:
        assert res.ci_low > 0 and res.p_value < 0.01 and res.verdict.startswith("treatment better")
        assert res.prob_improvement > 0.5
    else:
        assert res.p_value > 0.05 and "too wide to decide" in res.verdict
    assert comp.sources[ENV].kind == "training"


def test_bca_interval_covers_the_truth_about_95_percent_of_the_time() -> None:
    rng = np.random.default_rng(1)
    hits = 0
    for _ in range(200):
        base = rng.normal(0, 30, 12)
        treat = base + 3.0 + rng.normal(0, 5, 12)
        r = paired_difference(dict(enumerate(base)), dict(enumerate(treat)))
        hits += r.ci_low <= 3.0 <= r.ci_high
    assert 0.88 <= hits / 200 <= 0.99


def test_pairs_by_seed_not_by_folder_order(tmp_path: Path) -> None:
    # Folder names sort opposite to the seeds; the treatment is exactly baseline + 5 per seed.
    for s, luck in enumerate([50.0, 10.0, 90.0, 30.0]):
        base = {"env": ENV, "seed": s, "rllib_asor_run": "PPO"}
        write_trial(tmp_path, f"a_{9 - s}", base, [luck])
        write_trial(tmp_path, f"b_{s}", {**base, "asor": {"mode": "asor"}}, [luck + 5])
    (res,) = compare([tmp_path]).results
    assert res.seeds == [0, 1, 2, 3]
    assert res.diffs == [5.0] * 4 and res.ci_low == res.ci_high == 5.0


def test_groups_with_other_settings_are_never_lumped(tmp_path: Path) -> None:
    for s in range(3):
        base = {"env": ENV, "seed": s, "train_batch_size": 4000, "rllib_asor_run": "PPO"}
        write_trial(tmp_path / "seeds", f"ppo_{s}", base, [10.0 + s])
        for lam in (0.1, 0.3):
            asor = {**base, "learner_config_dict": {"asor": {"mode": "asor", "lambda_": lam}}}
            write_trial(tmp_path / "sweep", f"asor_{lam}_{s}", asor, [20.0 + s + lam])
    single = {"env": ENV, "seed": 0, "train_batch_size": 2000, "asor": {"mode": "asor"}}
    write_trial(tmp_path / "single", "PPO_single", single, [99.0])
    comp = compare([tmp_path])
    lam01, lam03 = (f"PPO+ASOR (asor.lambda_={lam}, train_batch_size=4000)" for lam in (0.1, 0.3))
    single_label = "PPO+ASOR (train_batch_size=2000)"
    assert {g.label: g.n for g in comp.groups} == {"PPO": 3, lam01: 3, lam03: 3, single_label: 1}
    for g in comp.groups:  # each group's trials share every setting but the seed
        assert len({json.dumps({k: v for k, v in t.params.items() if k != "seed"}, sort_keys=True)
                    for t in g.trials}) == 1  # fmt: skip
    by_treat = {r.treatment: r for r in comp.results}
    assert by_treat[lam03].pairs == 3 and by_treat[lam03].diff_mean == pytest.approx(10.3)
    assert by_treat[lam01].differs_in == ["asor.lambda_", "asor.mode"]
    single_res = by_treat[single_label]
    assert single_res.pairs == 1 and single_res.verdict.startswith("one pair")
    assert single_res.differs_in == ["asor.mode", "train_batch_size"]
    text = render_text(comp)
    assert "- PPO: 3 trial(s), seeds 0, 1, 2; asor.lambda_=<missing>" in text


def test_evaluation_returns_are_preferred_and_per_dynamics_rows(tmp_path: Path) -> None:
    for s in range(5):
        base = {"env": ENV, "seed": s, "rllib_asor_run": "PPO"}
        dyn = {"0": [0.0, 10.0 + s], "1": [0.0, 50.0 + s]}
        write_trial(
            tmp_path, f"p{s}", base, [1.0, 500.0], eval_returns=[0, 30.0 + s], eval_dynamics=dyn
        )
        tdyn = {"0": [0.0, 12.0 + s], "1": [0.0, 50.0 + s]}
        write_trial(tmp_path, f"a{s}", {**base, "asor": {"mode": "asor"}}, [1.0, 0.0],
                    eval_returns=[0, 31.0 + s], eval_dynamics=tdyn)  # fmt: skip
    comp = compare([tmp_path])
    assert comp.sources[ENV].kind == "evaluation"
    main, d0, d1 = comp.results
    assert main.dynamics is None and main.diff_mean == pytest.approx(1.0)  # not -500 (training)
    assert (d0.dynamics, d0.diff_mean, d1.dynamics, d1.diff_mean) == ("0", 2.0, "1", 0.0)
    assert d1.p_value == 1.0 and d1.p_adjusted == 1.0
    assert d1.verdict == "exploratory: Holm-adjusted p 1 over 2 dynamics; no difference observed"
    assert "evaluation return during training" in render_text(comp)


def test_final_evaluation_file_wins_and_groups_by_dynamics_id(tmp_path: Path) -> None:
    for s in range(4):
        base = {"env": ENV, "seed": s, "rllib_asor_run": "PPO"}
        ev = {"seed": 1000, "returns": [10.0 + s, 20.0 + s], "dynamics_ids": [0, 1]}
        write_trial(tmp_path, f"p{s}", base, [5.0], eval_returns=[7.0], evaluation=ev)
        tev = {"seed": 1000, "returns": [13.0 + s, 20.0 + s], "dynamics_ids": [0, 1]}
        write_trial(tmp_path, f"a{s}", {**base, "asor": {"mode": "asor"}}, [5.0], eval_returns=[7.0],
                    evaluation=tev)  # fmt: skip
    comp = compare([tmp_path])
    assert comp.sources[ENV].kind == "final-evaluation"
    assert [(r.dynamics, r.diff_mean) for r in comp.results] == [
        (None, 1.5),
        ("0", 3.0),
        ("1", 0.0),
    ]


def test_symlinked_experiment_folders_are_followed(tmp_path: Path) -> None:
    ab_folder(tmp_path / "real", 10.0, seeds=4)
    (tmp_path / "view").mkdir()
    os.symlink(tmp_path / "real" / "exp", tmp_path / "view" / "exp")
    (res,) = compare([tmp_path / "view"]).results
    assert res.pairs == 4
    (res,) = compare([tmp_path / "view", tmp_path / "real"]).results  # each trial once
    assert res.pairs == 4


def test_pairs_needed_formula() -> None:
    # n = ((1.96 + 0.84) * sd / delta)^2 = (2.8 * 10 / 2)^2 = 196 (with scipy's exact z's: 197)
    assert pairs_needed(2.0, 10.0) in (196, 197)
    assert pairs_needed(0.0, 10.0) is None
    r = paired_difference({0: 0.0, 1: 10.0, 2: 20.0}, {0: 5.0, 1: 5.0, 2: 25.0})
    assert "too wide to decide" in r.verdict and f"about {r.pairs_needed} pairs" in r.verdict


def parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="rllib compare")
    cli.add_arguments(parser)
    return parser.parse_args(argv)


def test_cli_json_keys_and_text(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ab_folder(tmp_path, 10.0, seeds=6)
    assert cli.run(parse([str(tmp_path), "--json"])) == 0
    rows = json.loads(capsys.readouterr().out)
    assert len(rows) == 1 and JSON_KEYS <= set(rows[0])
    assert rows[0]["metric"] == "env_runners/episode_return_mean" and rows[0]["pairs"] == 6
    assert cli.run(parse([str(tmp_path), "--baseline", "PPO+ASOR"])) == 0
    text = capsys.readouterr().out
    assert "| PPO | PPO+ASOR | 6 |" in text and "BCa" in text and "Wilcoxon" in text


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["{missing}"], "does not exist"),
        (["{root}", "--baseline", "SAC"], "no group is named"),
        (["{root}", "--metric", "no/such"], "nothing to compare"),
    ],
)
def test_cli_bad_input_is_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    ab_folder(tmp_path / "r", 1.0, seeds=3)
    argv = [a.format(root=tmp_path / "r", missing=tmp_path / "nope") for a in argv]
    assert cli.run(parse(argv)) == 2
    err = capsys.readouterr().err
    assert err.startswith("rllib compare: error: ") and err.count("\n") == 1 and message in err


def test_two_pairs_never_decide_even_when_the_interval_excludes_zero() -> None:
    r = paired_difference({0: 10.0, 1: 20.0}, {0: 11.0, 1: 47.0})
    assert r.ci_low > 0 and r.p_value == 0.5  # the bootstrap of 2 values spans [1, 27]
    assert r.verdict.startswith("too wide to decide") and r.pairs_needed >= 6


def test_compare_reads_the_keys_the_dynamics_callback_writes() -> None:
    from rllib_asor.evaluation import dynamics
    from rllib_asor.report import scores

    assert (scores.DYNAMICS, scores.RETURN_LEAF) == (dynamics.METRIC_GROUP, dynamics.RETURN_LEAF)
