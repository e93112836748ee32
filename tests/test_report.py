"""`rllib report`: tables, statistics and curves from a real Tune run and hand-written results."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.stats import trim_mean

from rllib_asor.cli import report as cli
from rllib_asor.report import render, summary

pytestmark = pytest.mark.heavy  # starts Ray or a subprocess: scheduled first (conftest)

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


# --------------------------------------------------------------------------- helpers


def write_trial(
    root: Path,
    experiment: str,
    trial: str,
    params: dict[str, Any],
    returns: list[float],
    steps_per_iter: int = 1000,
    extra: dict[str, list[float]] | None = None,
) -> Path:
    """A trial folder as Tune writes it for RLlib's new stack (nested result dicts)."""
    tdir = root / experiment / trial
    tdir.mkdir(parents=True)
    (tdir / "params.json").write_text(json.dumps(params))
    with (tdir / "result.json").open("w") as f:
        for i, ret in enumerate(returns, start=1):
            row: dict[str, Any] = {
                "env_runners": {"episode_return_mean": ret, "num_episodes": 3},
                "learners": {"default_policy": {"policy_loss": -0.1}},
                "num_env_steps_sampled_lifetime": i * steps_per_iter,
                "training_iteration": i,
                "time_this_iter_s": 0.5,
                "config": params,
            }
            for key, vals in (extra or {}).items():
                node = row
                *parents, leaf = key.split("/")
                for p in parents:
                    node = node.setdefault(p, {})
                node[leaf] = vals[i - 1]
            f.write(json.dumps(row) + "\n")
    return tdir


def parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="rllib report")
    cli.add_arguments(parser)
    return parser.parse_args(argv)


def table_rows(md: str, env: str) -> dict[str, list[str]]:
    """method -> cells of the table under `## env`."""
    section = md.split(f"## {env}\n", 1)[1].split("\n## ", 1)[0]
    rows = {}
    for line in section.splitlines():
        if line.startswith("| ") and not line.startswith("| method"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            rows[cells[0]] = cells
    return rows


def assert_png(path: Path) -> None:
    import matplotlib.image

    assert path.read_bytes()[:8] == PNG_MAGIC
    img = matplotlib.image.imread(path)
    assert img.ndim == 3 and img.shape[0] > 100 and img.shape[1] > 100


# --------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def tune_results(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real (tiny) Tune experiment: PPO on CartPole, 2 trials, 2 iterations each."""
    os.environ.setdefault("RAY_memory_monitor_refresh_ms", "0")
    import ray
    from ray import tune
    from ray.rllib.algorithms.ppo import PPOConfig

    storage = tmp_path_factory.mktemp("ray_results")
    started = not ray.is_initialized()
    if started:
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        config = (
            PPOConfig()
            .environment("CartPole-v1")
            .env_runners(num_env_runners=0)
            .training(train_batch_size=200, minibatch_size=100, num_epochs=1)
        )
        results = tune.Tuner(
            "PPO",
            param_space=config,
            tune_config=tune.TuneConfig(num_samples=2),
            run_config=tune.RunConfig(
                name="cartpole-ppo",
                stop={"training_iteration": 2},
                storage_path=str(storage),
                checkpoint_config=tune.CheckpointConfig(checkpoint_at_end=False),
                verbose=0,
            ),
        ).fit()
        assert not results.errors
    finally:
        if started:
            ray.shutdown()
    return storage


@pytest.fixture
def fixture_results(tmp_path: Path) -> Path:
    """Several experiments, methods, seeds and envs with known final returns."""
    root = tmp_path / "results"
    lava = {"env": "LavaWorld-v0", "seed": 0}
    # Plain PPO, 3 seeds: finals 10, 20, 30.
    for seed, final in enumerate([10.0, 20.0, 30.0]):
        write_trial(
            root,
            "lava-ppo",
            f"PPO_LavaWorld-v0_aaaaa_0000{seed}_{seed}",
            {**lava, "seed": seed},
            [0.0, final / 2, final],
        )
    # PPO+ASOR (mode in learner_config_dict), 5 seeds with an outlier, race/asor metrics.
    for seed, final in enumerate([40.0, 50.0, 60.0, 70.0, 500.0]):
        write_trial(
            root,
            "lava-ppo-asor",
            f"PPO_LavaWorld-v0_bbbbb_0000{seed}_{seed}",
            {
                **lava,
                "seed": seed,
                "learner_config_dict": {"asor": {"mode": "asor", "lambda_": 0.1}},
            },
            [1.0, 2.0, final],
            extra={
                "env_runners/race/success_rate": [0.0, 0.5, 0.1 * seed],
                "learners/__all_modules__/asor/disc_acc": [0.5, 0.6, 0.7],
                "asor/rnd_loss": [0.3, 0.2, 0.1],
            },
        )
    # PPO+SRPO (top-level `asor` block), ASOR(count): one trial each.
    write_trial(
        root,
        "lava-srpo",
        "AsorPPO_LavaWorld-v0_ccccc_00000_0",  # our ASOR trainable (rllib_asor.rllib.trainable)
        {**lava, "asor": {"mode": "srpo"}},
        [5.0, 6.0],
    )
    write_trial(
        root,
        "lava-count",
        "PPO_LavaWorld-v0_ddddd_00000_0",
        {**lava, "asor": {"mode": "count"}},
        [7.0, 8.0],
    )
    # Second env; algorithm only in the experiment name, AsorConfig written as its repr.
    half = {"env": "HalfCheetahShift-v0"}
    for seed, final in enumerate([100.0, 200.0]):
        write_trial(
            root,
            "mujoco-sac-asor",
            f"trial_{seed}",
            {
                **half,
                "seed": seed,
                "learner_config_dict": {
                    "asor": "AsorConfig(lambda_=0.01, mode='srpo', proxy='rnd')"
                },
            },
            [final / 2, final],
            steps_per_iter=4000,
        )
    write_trial(root, "mujoco-cql", "CQL_HalfCheetahShift-v0_eeeee_00000_0", half, [1.0, 3.0])
    return root


# --------------------------------------------------------------------------- real Tune run


def test_report_on_real_tune_run_matches_result_json(tune_results: Path, tmp_path: Path) -> None:
    out = tmp_path / "report"
    md_path = render.make_report(tune_results, out)
    assert md_path == out / "report.md"
    md = md_path.read_text()

    finals, steps = [], []
    for rj in sorted(tune_results.rglob("result.json")):
        last = json.loads(rj.read_text().splitlines()[-1])
        finals.append(last["env_runners"]["episode_return_mean"])
        steps.append(last["num_env_steps_sampled_lifetime"])
    assert len(finals) == 2

    row = table_rows(md, "CartPole-v1")["PPO"]
    assert row[1] == "2"
    assert row[2] == f"{np.mean(finals):.2f} ± {np.std(finals, ddof=1):.2f}"
    assert row[5] == f"{np.mean(steps):,.0f}"
    summary = json.loads((out / "summary.json").read_text())
    (group,) = summary["groups"]
    assert group["method"] == "PPO" and group["env"] == "CartPole-v1"
    assert group["mean"] == pytest.approx(np.mean(finals))
    lo, hi = group["ci95"]
    assert lo <= group["mean"] <= hi
    assert_png(out / "curves_CartPole-v1.png")


def test_report_default_out_dir_is_inside_results_and_rerun_ignores_it(tune_results: Path) -> None:
    md = render.make_report(tune_results)
    assert md == tune_results / "report" / "report.md"
    again = render.make_report(tune_results)  # the report folder holds no result.json
    assert "| PPO | 2 |" in again.read_text()


# --------------------------------------------------------------------------- grouping, numbers


def test_methods_grouped_by_asor_mode_algo_and_env(fixture_results: Path, tmp_path: Path) -> None:
    md = render.make_report(fixture_results, tmp_path / "out").read_text()
    lava = table_rows(md, "LavaWorld-v0")
    assert set(lava) == {"PPO", "PPO+ASOR", "PPO+SRPO", "PPO+ASOR(count)"}
    half = table_rows(md, "HalfCheetahShift-v0")
    assert set(half) == {"SAC+SRPO", "CQL"}
    assert [lava["PPO"][1], lava["PPO+ASOR"][1], half["SAC+SRPO"][1], half["CQL"][1]] == [
        "3",
        "5",
        "2",
        "1",
    ]


def test_algorithm_comes_from_the_run_rllib_train_records_not_the_folder_names(
    tmp_path: Path,
) -> None:
    """`rllib train` writes the experiment's `run` into every trial's params; it wins over the
    folder names (here misleading), which are only a fallback for other results."""
    from rllib_asor.report.results import RUN_KEY

    params = {"env": "LavaWorld-v0", RUN_KEY: "SAC", "asor": {"mode": "asor"}}
    write_trial(tmp_path, "ppo-sweep", "PPO_LavaWorld-v0_fffff_00000_0", params, [1.0, 2.0])
    write_trial(
        tmp_path,
        "ppo-sweep",
        "APPO_LavaWorld-v0_fffff_00001_1",
        {**params, RUN_KEY: "DQN", "asor": None},
        [3.0],
    )
    rep = summary.summarize(tmp_path)
    assert sorted(t.method for t in rep.trials) == ["DQN", "SAC+ASOR"]


def test_final_mean_std_ci_iqm_match_known_values(fixture_results: Path) -> None:
    rep = summary.summarize(fixture_results)
    g = {(s.env, s.method): s for s in rep.groups}
    ppo = g[("LavaWorld-v0", "PPO")]
    assert ppo.finals == [10.0, 20.0, 30.0]
    assert ppo.mean == pytest.approx(20.0)
    assert ppo.std == pytest.approx(10.0)  # sample std
    assert ppo.ci_low <= ppo.mean <= ppo.ci_high
    assert 10.0 <= ppo.ci_low < ppo.ci_high <= 30.0
    asor = g[("LavaWorld-v0", "PPO+ASOR")]
    assert asor.mean == pytest.approx(144.0)
    assert asor.iqm == pytest.approx(60.0)  # 40 and 500 trimmed away
    assert asor.iqm == pytest.approx(trim_mean([40, 50, 60, 70, 500], 0.25))
    assert asor.ci_low <= asor.mean <= asor.ci_high
    assert g[("HalfCheetahShift-v0", "SAC+SRPO")].env_steps == pytest.approx(8000.0)
    single = g[("HalfCheetahShift-v0", "CQL")]
    assert single.n == 1 and single.std == 0.0 and np.isnan(single.ci_low)


def test_table_rows_show_formatted_statistics(fixture_results: Path, tmp_path: Path) -> None:
    md = render.make_report(fixture_results, tmp_path / "out").read_text()
    ppo = table_rows(md, "LavaWorld-v0")["PPO"]
    assert ppo[2] == "20.00 ± 10.00"
    assert ppo[4] == "20.00"  # IQM
    assert ppo[5] == "3,000"  # env steps
    lo, hi = (float(v) for v in ppo[3].strip("[]").split(","))
    assert lo <= 20.0 <= hi
    assert table_rows(md, "HalfCheetahShift-v0")["CQL"][3] == "n/a (1 trial)"


def test_race_and_asor_metrics_become_extra_columns(fixture_results: Path, tmp_path: Path) -> None:
    md = render.make_report(fixture_results, tmp_path / "out").read_text()
    header = next(line for line in md.splitlines() if line.startswith("| method"))
    assert "`env_runners/race/success_rate`" in header
    assert "`learners/__all_modules__/asor/disc_acc`" in header
    rep = summary.summarize(fixture_results)
    asor = next(g for g in rep.groups if g.method == "PPO+ASOR")
    mean, _ = asor.extra["env_runners/race/success_rate"]
    assert mean == pytest.approx(np.mean([0.0, 0.1, 0.2, 0.3, 0.4]))
    ppo = next(g for g in rep.groups if g.method == "PPO" and g.env == "LavaWorld-v0")
    assert np.isnan(ppo.extra["env_runners/race/success_rate"][0])  # plain PPO has no race metric
    assert table_rows(md, "LavaWorld-v0")["PPO"][6:] == ["n/a", "n/a"]


def test_columns_option_selects_extra_columns(fixture_results: Path) -> None:
    rep = summary.summarize(fixture_results, columns=["time_this_iter_s"])
    assert rep.columns == ["time_this_iter_s"]
    assert rep.groups[0].extra["time_this_iter_s"][0] == pytest.approx(0.5)
    args = parse([str(fixture_results), "--columns", "a/b,c", "--columns", "d"])
    assert args.columns == ["a/b", "c", "d"]


def test_default_columns_are_race_and_headline_asor_metrics_all_shows_every_one(
    fixture_results: Path,
) -> None:
    default = summary.summarize(fixture_results).columns
    assert default == ["env_runners/race/success_rate", "learners/__all_modules__/asor/disc_acc"]
    assert summary.summarize(fixture_results, columns=["all"]).columns == ["asor/rnd_loss", *default]


def test_last_n_averages_the_last_iterations(fixture_results: Path) -> None:
    rep = summary.summarize(fixture_results, last_n=2)
    ppo = next(g for g in rep.groups if g.method == "PPO" and g.env == "LavaWorld-v0")
    assert ppo.finals == [7.5, 15.0, 22.5]


def test_group_by_dotted_param_key_still_splits_other_settings(fixture_results: Path) -> None:
    rep = summary.summarize(fixture_results, group_by="asor.lambda_")
    methods = {g.method: g.n for g in rep.groups if g.env == "LavaWorld-v0"}
    assert methods == {
        "asor.lambda_=0.1": 5,
        "asor.lambda_=<missing>": 3,  # plain PPO
        "asor.lambda_=<missing> (asor.mode=srpo)": 1,  # never lumped with PPO
        "asor.lambda_=<missing> (asor.mode=count)": 1,
    }


def test_trials_whose_settings_differ_are_never_seeds_of_one_group(tmp_path: Path) -> None:
    """A mixed results folder: a λ sweep at another budget, a single run and three seeds, all
    PPO+ASOR: four groups, each labelled by what sets it apart, the keys listed in report.md."""
    asor = {"env": "MyEnv-v0", "rllib_asor_run": "PPO", "train_batch_size": 4000}
    for lam in (0.01, 0.1, 1.0):
        params = {**asor, "seed": 0, "train_batch_size": 2000, "asor": {"lambda_": lam}}
        write_trial(tmp_path, "sweep", f"PPO_{lam}", params, [1.0, 2.0])
    write_trial(tmp_path, "single", "PPO_single", {**asor, "asor": {"mode": "asor"}}, [5.0])
    for seed in range(3):
        params = {**asor, "seed": seed, "asor": {"mode": "asor"}}
        write_trial(tmp_path, "seeds", f"PPO_{seed}", params, [float(seed)])
    rep = summary.summarize(tmp_path)
    sizes = {g.method: g.n for g in rep.groups}
    assert sizes == {
        # the single run (no seed set) and the three seeds: the same settings
        "PPO+ASOR (asor.mode=asor, train_batch_size=4000)": 4,
        "PPO+ASOR (asor.lambda_=0.01, train_batch_size=2000)": 1,
        "PPO+ASOR (asor.lambda_=0.1, train_batch_size=2000)": 1,
        "PPO+ASOR (asor.lambda_=1.0, train_batch_size=2000)": 1,
    }
    md = render.make_report(tmp_path, tmp_path / "out").read_text()
    assert "- PPO+ASOR (asor.lambda_=0.1, train_batch_size=2000): `asor.lambda_`=0.1" in md
    assert "scipy BCa, 5,000 resamples" in md


def test_curves_png_per_env_and_no_temp_files_left(fixture_results: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    md = render.make_report(fixture_results, out).read_text()
    for env in ("LavaWorld-v0", "HalfCheetahShift-v0"):
        assert_png(out / f"curves_{env}.png")
        assert f"](curves_{env}.png)" in md
    assert sorted(p.name for p in out.iterdir()) == [
        "curves_HalfCheetahShift-v0.png",
        "curves_LavaWorld-v0.png",
        "report.md",
        "summary.json",
    ]


def test_restored_trial_keeps_last_report_and_skips_broken_line(tmp_path: Path) -> None:
    tdir = write_trial(tmp_path, "exp", "PPO_X_0", {"env": "X"}, [1.0, 2.0, 3.0])
    with (tdir / "result.json").open("a") as f:  # iteration 3 re-run after restore, then a crash
        f.write(
            json.dumps(
                {
                    "env_runners": {"episode_return_mean": 9.0},
                    "num_env_steps_sampled_lifetime": 3000,
                    "training_iteration": 3,
                }
            )
            + "\n"
        )
        f.write('{"env_runners": {"episode_ret')
    rep = summary.summarize(tmp_path)
    (trial,) = rep.trials
    assert len(trial.rows) == 3
    assert rep.groups[0].finals == [9.0]
    assert any("unreadable" in n for n in rep.notes)


def test_missing_x_falls_back_to_training_iteration(tmp_path: Path) -> None:
    tdir = tmp_path / "exp" / "PPO_X_0"
    tdir.mkdir(parents=True)
    (tdir / "params.json").write_text(json.dumps({"env": "X"}))
    (tdir / "result.json").write_text(
        "".join(
            json.dumps({"env_runners": {"episode_return_mean": float(i)}, "training_iteration": i})
            + "\n"
            for i in (1, 2)
        )
    )
    rep = summary.summarize(tmp_path)
    assert rep.x == "training_iteration"
    assert any("training_iteration" in n for n in rep.notes)
    assert rep.groups[0].env_steps == 2.0


# --------------------------------------------------------------------------- errors, CLI


def test_bad_inputs_raise_value_error_with_clear_message(
    tmp_path: Path, fixture_results: Path
) -> None:
    with pytest.raises(ValueError, match="does not exist"):
        render.make_report(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="no trial results"):
        render.make_report(tmp_path / "empty")
    with pytest.raises(
        ValueError, match="episode_return_meen.*similar keys: env_runners/episode_return_mean"
    ):
        render.make_report(fixture_results, metric="env_runners/episode_return_meen")


@pytest.mark.parametrize("case", ["missing", "empty", "bad-metric"])
def test_cli_exits_2_with_one_line_for_bad_input(
    case: str, tmp_path: Path, fixture_results: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "empty").mkdir()
    argv = {
        "missing": [str(tmp_path / "nope")],
        "empty": [str(tmp_path / "empty")],
        "bad-metric": [str(fixture_results), "--metric", "no/such/key"],
    }[case]
    assert cli.run(parse(argv)) == 2
    err = capsys.readouterr().err
    assert err.startswith("rllib report: error: ") and err.count("\n") == 1
    assert "Traceback" not in err


def test_cli_success_writes_report_and_prints_path(
    fixture_results: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "rep"
    args = parse([str(fixture_results), "--out", str(out), "--last-n", "2"])
    assert (args.metric, args.x) == (summary.DEFAULT_METRIC, summary.DEFAULT_X)
    assert cli.run(args) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[-1] == f"report: {out / 'report.md'}"
    assert lines[0].startswith(("Paired answer", "Unpaired"))
    assert "last 2 iteration(s)" in (out / "report.md").read_text()


def test_headline_columns_show_each_metric_once_without_per_map_copies() -> None:
    keys = [
        "race/success_rate", "env_runners/race/success_rate", "race/map_7/success_rate",
        "env_runners/race/map_7/success_rate", "race/trapped_rate", "race/curriculum_stage",
        "asor/disc_acc", "asor/rnd_loss", "asor/p0/disc_acc", "asor/bonus_share",
    ]
    assert summary.headline_columns(keys) == [
        "asor/bonus_share", "asor/disc_acc", "race/success_rate", "race/trapped_rate",
    ]


def test_one_bootstrap_ci_for_reports_and_studies() -> None:
    """`rllib report` uses `rllib_asor.report.stats.bootstrap_ci` (the studies' tables import the
    same function: studies/tests/test_compare.py checks that side)."""
    import numpy as np

    from rllib_asor.report.stats import bootstrap_ci

    assert summary.bootstrap_ci is bootstrap_ci
    lo, hi = bootstrap_ci([0.1, 0.5, 0.7, 0.2, 0.9])
    assert lo < float(np.mean([0.1, 0.5, 0.7, 0.2, 0.9])) < hi
    assert (lo, hi) == bootstrap_ci([0.1, 0.5, 0.7, 0.2, 0.9])  # seeded: reproducible
    assert bootstrap_ci([3.0, 3.0]) == (3.0, 3.0)
    assert all(np.isnan(bootstrap_ci([1.0])))
