"""Nothing wrong in a file runs silently: every stop key is a metric the algorithm reports, a
value of the wrong type names its key, and `--test` / `--dry-run` check the file as written
before replacing its `stop:` and parts of its `config:`. One line on stderr, exit 2."""

from __future__ import annotations

import math

import pytest

from rllib_asor.cli import legacy
from rllib_asor.cli.main import main
from rllib_asor.cli.spec import parse_experiment
from rllib_asor.cli.stop_keys import Catalogue


def _yaml(write_yaml, stop: str, config: str = "", run: str = "PPO", env: str = "CartPole-v1"):
    return write_yaml(f"x:\n  env: {env}\n  run: {run}\n  stop: {{{stop}}}\n  config: {{{config}}}\n")


def _refused(capsys, argv, *fragments):
    assert main(argv) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return lines[0]


@pytest.mark.parametrize("extra", [[], ["--test"]])
def test_a_misspelled_stop_key_is_refused_even_with_test(write_yaml, capsys, extra):
    path = _yaml(write_yaml, "num_env_steps_sampled_lifetim: 20000")
    _refused(capsys, ["train", "file", path, "--dry-run", *extra],
             "x.stop.num_env_steps_sampled_lifetim", "not a metric PPO reports",
             "did you mean num_env_steps_sampled_lifetime")  # fmt: skip


@pytest.mark.parametrize(
    ("stop", "config", "fragment"),
    [
        ("episode_return_mean: 100", "", "did you mean env_runners/episode_return_mean"),
        ("env_runners/episode_retrun_mean: 100", "", "did you mean env_runners/episode_return_mean"),
        ("evaluation/env_runners/episode_return_mean: 1", "", "set config.evaluation_interval"),
        ("asor/disc_loss: 1", "", "only with an asor: block"),
        ("race/success_rate: 0.5", "", "only on the race envs"),
        ("learners/default_policy/qf_loss: 1", "", "not a metric PPO reports"),
        ("replay_buffer/num_env_steps_added: 1", "", "PPO has no replay buffer"),
    ],
)
def test_stop_keys_the_algorithm_does_not_report(write_yaml, capsys, stop, config, fragment):
    path = _yaml(write_yaml, stop, config)
    _refused(capsys, ["train", "file", path, "--dry-run"], "x.stop.", fragment)


@pytest.mark.parametrize(
    ("run", "env", "stop", "config"),
    [
        ("PPO", "CartPole-v1", "training_iteration: 3, time_total_s: 60, "
         "num_env_steps_sampled_lifetime: 1000, env_runners/episode_return_mean: 100, "
         "learners/default_policy/vf_loss: 0.1, env_runners/episode_reward_mean: 1", ""),
        ("PPO", "CartPole-v1", "evaluation/env_runners/episode_return_mean: 1, asor/disc_acc: 0.6",
         "evaluation_interval: 1, asor: {seed: 0}"),
        ("SAC", "Pendulum-v1", "learners/default_policy/qf_loss: 1, timesteps_total: 1000, "
         "replay_buffer/num_env_steps_added_lifetime: 10", ""),
    ],
)  # fmt: skip
def test_stop_keys_the_algorithm_reports_pass(write_yaml, capsys, run, env, stop, config):
    assert main(["train", "file", _yaml(write_yaml, stop, config, run, env), "--dry-run"]) == 0


def test_a_misspelled_stop_flag_is_refused(write_yaml, capsys):
    path = _yaml(write_yaml, "training_iteration: 2")
    _refused(capsys, ["train", "file", path, "--dry-run", "--test", "--stop", "time_totl_s=5"],
             "x.stop.time_totl_s", "did you mean time_total_s")  # fmt: skip


def test_own_callbacks_may_name_their_own_metrics(write_yaml, capsys):
    path = _yaml(write_yaml, "env_runners/my_own_count: 5",
                 "callbacks: rllib_asor.evaluation.dynamics.DynamicsReturnsCallback")  # fmt: skip
    assert main(["train", "file", path, "--dry-run"]) == 0
    assert "stops the run only if your callbacks log it" in capsys.readouterr().err


SAC_N_STEP = """
pendulum-sac:
    env: Pendulum-v1
    run: SAC
    stop: {episode_reward_mean: -150, timesteps_total: 30000}
    config:
        framework: tf
        horizon: 200
        Q_model: {fcnet_hiddens: [256, 256]}
        n_step: 3
        rollout_fragment_length: 1
        learning_starts: 256
        timesteps_per_iteration: 1000
        num_workers: 0
"""


@pytest.mark.parametrize("extra", [[], ["--test"]])
def test_n_step_longer_than_the_fragment_runs_as_old_rllib_ran_it(write_yaml, capsys, extra):
    """Ray's old pendulum-sac.yaml: old RLlib raised the fragment to n_step, RLlib 2.60's own
    check refuses it (with "'int' object is not subscriptable": its message indexes an int
    n_step). The fragment is raised, with one warning line (tests/cli/test_old_files.py)."""
    path = write_yaml(SAC_N_STEP)
    assert main(["train", "file", path, "--dry-run", *extra]) == 0
    err = capsys.readouterr().err
    assert err.count("'rollout_fragment_length: 1' translated to 'rollout_fragment_length: 3'") == 1


@pytest.mark.parametrize("extra", [[], ["--test"]])
def test_a_grid_of_n_step_longer_than_the_fragment_is_one_line_naming_both(
    write_yaml, capsys, extra
):
    """A grid has no one fragment old RLlib would have used: refused, naming both keys."""
    path = write_yaml(SAC_N_STEP.replace("n_step: 3", "n_step: {grid_search: [1, 3]}"))
    line = _refused(capsys, ["train", "file", path, "--dry-run", *extra],
                    ".config.n_step:", "n_step: 3", "rollout_fragment_length: 1",
                    "allowed: rollout_fragment_length: auto or an integer >= 3")  # fmt: skip
    assert "subscriptable" not in line


@pytest.mark.parametrize("drop", ["n_step: 3\n", "rollout_fragment_length: 1\n"])
def test_either_n_step_or_a_short_fragment_alone_passes(write_yaml, capsys, drop):
    path = write_yaml(SAC_N_STEP.replace(drop, "\n"))
    assert main(["train", "file", path, "--dry-run"]) == 0


@pytest.mark.parametrize("extra", [[], ["--test"]])
@pytest.mark.parametrize(
    ("config", "fragments"),
    [
        ('train_batch_size: "lots"', ("x.config.train_batch_size", "'lots' is invalid",
                                       "allowed an integer")),
        ("gamma: high", ("x.config.gamma", "'high' is invalid", "allowed a number")),
        ("num_epochs: 2.5", ("x.config.num_epochs", "2.5 is invalid", "allowed an integer")),
        ("use_gae: 'yes'", ("x.config.use_gae", "'yes' is invalid", "allowed true or false")),
        ("lr: {grid_search: [0.001, fast]}", ("x.config.lr", "'fast' is invalid", "a number")),
        ("model_config: [64, 64]", ("x.config.model_config", "allowed a mapping")),
    ],
)  # fmt: skip
def test_a_wrong_type_names_key_value_and_type(write_yaml, capsys, config, fragments, extra):
    path = _yaml(write_yaml, "training_iteration: 2", config)
    _refused(capsys, ["train", "file", path, "--dry-run", *extra], *fragments)


def test_numbers_yaml_reads_as_text_are_read_as_numbers(write_yaml, capsys):
    path = _yaml(write_yaml, "training_iteration: 2",
                 "lr: 5e-5, train_batch_size: 1e3, num_cpus_per_env_runner: 0.5")  # fmt: skip
    assert main(["train", "file", path, "--dry-run"]) == 0
    captured = capsys.readouterr()
    assert "'5e-5' read as the number 5e-05" in captured.err
    assert "lr: 5.0e-05" in captured.out and "train_batch_size: 1000" in captured.out


def test_the_catalogue_covers_every_metric_of_a_real_iteration(cli_ray):
    """One real PPO iteration (with evaluation) and one SAC iteration: every number they
    report is accepted as a stop key, and every legacy stop name lands on a key they report."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.algorithms.sac import SACConfig
    from ray.tune.utils import flatten_dict

    runs = {
        # 256 steps and a fixed seed: episodes end in the iteration (their return is reported)
        "PPO": ("CartPole-v1", PPOConfig().training(train_batch_size=256, minibatch_size=128,
                                                    num_epochs=1).debugging(seed=0)
                .evaluation(evaluation_interval=1, evaluation_duration=1)),
        "SAC": ("Pendulum-v1", SACConfig().training(train_batch_size=16,
                                                    num_steps_sampled_before_learning_starts=20)
                .reporting(min_sample_timesteps_per_iteration=40)),
    }  # fmt: skip
    reported: dict[str, set[str]] = {}
    for run, (env, cfg) in runs.items():
        cfg = cfg.environment(env).env_runners(num_env_runners=0)
        algo = cfg.build_algo()
        try:
            result = flatten_dict(algo.train(), delimiter="/")
        finally:
            algo.stop()
        numbers = {
            k for k, v in result.items()
            if isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            and not k.startswith("config/") and k not in ("pid", "done")
        }  # fmt: skip
        evaluation = "evaluation_interval: 1" if run == "PPO" else ""
        exp = parse_experiment("x", {"run": run, "env": env, "config": {}}, "f.yaml")
        catalogue = Catalogue(exp, cfg)
        catalogue.evaluation = bool(evaluation)
        missing = sorted(k for k in numbers if not catalogue.knows(k))
        assert not missing, (run, missing)
        reported[run] = numbers
    for old, new in legacy.RENAMED_STOP_KEYS.items():
        assert new in reported["PPO"], (old, new)


def test_rllib_ab_turns_evaluation_on_so_its_stop_keys_pass():
    from rllib_asor.cli.errors import UsageError
    from rllib_asor.cli.validate import check_file

    spec = {"run": "PPO", "env": "CartPole-v1",
            "stop": {"evaluation/env_runners/episode_return_mean": 100}}  # fmt: skip
    check_file(parse_experiment("x", spec, "f.yaml"), evaluation=True)  # what `rllib ab` does
    with pytest.raises(UsageError, match="evaluation_interval"):
        check_file(parse_experiment("x", spec, "f.yaml"))


def test_an_offline_run_reports_no_env_runner_episodes(tmp_path):
    from rllib_asor.cli.errors import UsageError
    from rllib_asor.cli.validate import check_file

    config = {"input": str(tmp_path / "data"), "evaluation_interval": 1, "lr": None,
              "dataset_num_iters_per_learner": 1}
    spec = {"run": "CQL", "env": "Pendulum-v1", "config": config,
            "stop": {"env_runners/episode_return_mean": -200}}  # fmt: skip
    with pytest.raises(UsageError, match="offline run .* steps no env"):
        check_file(parse_experiment("x", spec, "f.yaml"))
    spec["stop"] = {"evaluation/env_runners/episode_return_mean": -200, "training_iteration": 5}
    check_file(parse_experiment("x", spec, "f.yaml"))
