"""Bad input: one line on stderr naming the file, key and allowed values; exit 2; no traceback."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from rllib_asor.cli.main import main

STOP = "  stop: {training_iteration: 2}\n"  # a file with one problem has a stop
GOOD_HEAD = "x:\n  env: CartPole-v1\n  run: PPO\n" + STOP


def _run(capsys, argv):
    rc = main(argv)
    err = capsys.readouterr().err
    return rc, err


def _assert_one_line(err: str, *fragments: str) -> None:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for f in fragments:
        assert f in lines[0], lines[0]


def test_unknown_config_key_exits_2_with_file_key_and_allowed(write_yaml, capsys):
    path = write_yaml(GOOD_HEAD + "  config: {lr: 0.1, num_sgd_iters: 3}\n")
    rc, err = _run(capsys, ["train", "file", path])
    assert rc == 2
    _assert_one_line(err, path, "x.config.num_sgd_iters", "unknown key for PPO", "allowed:")


def test_asor_on_an_unsupported_run_names_every_run_it_takes(write_yaml, capsys):
    path = write_yaml("x:\n  env: CartPole-v1\n  run: DQN\n" + STOP + "  config: {asor: {}}\n")
    rc, err = _run(capsys, ["train", "file", path, "--dry-run"])
    assert rc == 2
    _assert_one_line(err, path, "x.run", "ASOR does not support 'DQN'",
                     "allowed: CQL, ESCP, MAPLE, PPO, SAC", "FastSAC", "OSI", "CaDM")  # fmt: skip


def test_unknown_key_suggests_close_match(write_yaml, capsys):
    rc, err = _run(capsys, ["train", "file", write_yaml(GOOD_HEAD + "  config: {num_epoch: 3}\n")])
    assert rc == 2
    _assert_one_line(err, "did you mean num_epochs")


def test_unknown_experiment_level_key_exits_2(write_yaml, capsys):
    rc, err = _run(capsys, ["train", "file", write_yaml(GOOD_HEAD + "  stopp: {}\n")])
    assert rc == 2
    _assert_one_line(err, "x.stopp", "allowed: env, run, stop, config, checkpoint_config")


def test_broken_yaml_exits_2_naming_line(write_yaml, capsys):
    path = write_yaml(GOOD_HEAD + "  config: {lr: [0.1\n")
    rc, err = _run(capsys, ["train", "file", path])
    assert rc == 2
    _assert_one_line(err, path, "invalid YAML: line")


def test_missing_file_exits_2(tmp_path, capsys):
    path = str(tmp_path / "nope.yaml")
    rc, err = _run(capsys, ["train", "file", path])
    assert rc == 2
    _assert_one_line(err, path, "file not found")


@pytest.mark.parametrize(
    ("block", "fragment"),
    [
        ("{rho_value: 1.5}", "asor.rho_value=1.5 is invalid: allowed a number in (0, 1]"),
        ("{rho_count: 0}", "asor.rho_count=0 is invalid: allowed a number in (0, 1]"),
        ("{lambda_: -0.1}", "asor.lambda_=-0.1 is invalid"),
        ("{lambda: -1}", "asor.lambda_=-1 is invalid"),
        ("{rho_value: {grid_search: [0.5, 2.0]}}", "asor.rho_value=2.0 is invalid"),
        ("{lambda_: {grid_search: [0.1, -1]}}", "asor.lambda_=-1 is invalid"),
        ("{proxy: counts}", "allowed rnd | ensemble"),
        ("{rhovalue: 0.5}", "asor: unknown key(s) 'rhovalue'"),
    ],
)
def test_bad_asor_block_exits_2(write_yaml, capsys, block, fragment):
    path = write_yaml(GOOD_HEAD + f"  config:\n    asor: {block}\n")
    rc, err = _run(capsys, ["train", "file", path])
    assert rc == 2
    _assert_one_line(err, path, "x.config.asor", fragment)


def test_unknown_env_id_exits_2_listing_ours(write_yaml, capsys):
    path = write_yaml("x:\n  env: NoSuchEnv-v9\n  run: PPO\n" + STOP)
    rc, err = _run(capsys, ["train", "file", path])
    assert rc == 2
    _assert_one_line(err, path, "x.env", "'NoSuchEnv-v9'", "rllib_asor/LavaWorld-v0", "CartPole-v1")


def test_unknown_algorithm_exits_2(write_yaml, capsys):
    path = write_yaml("x:\n  env: CartPole-v1\n  run: PPOO\n" + STOP)
    rc, err = _run(capsys, ["train", "file", path])
    assert rc == 2
    _assert_one_line(err, "x.run", "unknown algorithm 'PPOO'", "PPO")


def test_empty_grid_search_exits_2(write_yaml, capsys):
    path = write_yaml(GOOD_HEAD + "  config: {lr: {grid_search: []}}\n")
    rc, err = _run(capsys, ["train", "file", path])
    assert rc == 2
    _assert_one_line(err, "x.config.lr.grid_search", "non-empty list")


def test_bad_config_json_flag_exits_2(capsys):
    rc, err = _run(capsys, ["train", "--run", "PPO", "--env", "CartPole-v1", "--config", "{lr:"])
    assert rc == 2
    _assert_one_line(err, "--config", "invalid JSON")


def test_resume_without_previous_run_exits_2(tmp_path, capsys):
    argv = [
        "train",
        "--run",
        "PPO",
        "--env",
        "CartPole-v1",
        "--storage-path",
        str(tmp_path),
        "--stop",
        "training_iteration=2",
        "--resume",
    ]
    rc, err = _run(capsys, argv)
    assert rc == 2
    _assert_one_line(err, "--resume", "no previous run to resume at", str(tmp_path))


def test_unreachable_address_fails_fast_with_exit_2(capsys):
    t0 = time.monotonic()
    rc, err = _run(
        capsys,
        ["train", "--run", "PPO", "--env", "CartPole-v1", "--test", "--address", "127.0.0.1:1"],
    )
    assert rc == 2
    assert time.monotonic() - t0 < 30
    _assert_one_line(err, "--address", "cannot reach a Ray cluster at 127.0.0.1:1")


def test_evaluate_missing_checkpoint_exits_2(tmp_path, capsys):
    rc, err = _run(capsys, ["evaluate", str(tmp_path / "none"), "--episodes", "2"])
    assert rc == 2
    _assert_one_line(err, "not found")


def test_console_script_prints_one_line_and_exits_2(write_yaml):
    """The installed entry point (a real subprocess): no traceback, no Ray noise."""
    path = write_yaml(GOOD_HEAD + "  config: {num_workers: 2, bogus_key: 1}\n")
    proc = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys; from rllib_asor.cli.main import main; sys.exit(main())",
            "train",
            "file",
            path,
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    _assert_one_line(proc.stderr, path, "x.config.bogus_key", "allowed:")


@pytest.mark.parametrize(
    "argv",
    [["train", "--num-env-runners", "abc"], ["evaluate"], [], ["nonsense"]],
)
def test_usage_errors_return_2_with_one_line(capsys, argv):
    rc, err = _run(capsys, argv)
    assert rc == 2
    _assert_one_line(err, "error:")


def test_help_returns_0(capsys):
    assert main(["train", "--help"]) == 0
    assert "rllib train file PATH" in capsys.readouterr().out


def test_bad_checkpoint_config_value_exits_2(write_yaml, capsys):
    path = write_yaml(GOOD_HEAD + "  checkpoint_config: {num_to_keep: 0}\n")
    rc, err = _run(capsys, ["train", "file", path])
    assert rc == 2
    _assert_one_line(err, path, "x.checkpoint_config", "num_to_keep")


def test_curriculum_on_a_non_race_env_exits_2(write_yaml, capsys):
    path = write_yaml(GOOD_HEAD + "  config: {curriculum: {stages: [2]}}\n")
    rc, err = _run(capsys, ["train", "file", path])
    assert rc == 2
    _assert_one_line(err, "x.config.curriculum", "allowed envs: game_env/")


def test_bad_curriculum_stage_exits_2(write_yaml, capsys):
    head = "x:\n  env: game_env/ObstacleRace-v0\n  run: PPO\n" + STOP
    path = write_yaml(head + "  config: {curriculum: {stages: [[2], [12]]}}\n")
    rc, err = _run(capsys, ["train", "file", path])
    assert rc == 2
    _assert_one_line(err, "x.config.curriculum", "stage 1", "allowed: 0..9")


def test_asor_key_typo_suggests_the_key_and_is_not_cut(write_yaml, capsys):
    rc, err = _run(
        capsys, ["train", "file", write_yaml(GOOD_HEAD + "  config: {asor: {lamda_: 0.1}}\n")]
    )
    assert rc == 2
    _assert_one_line(err, "'lamda_' (did you mean 'lambda_'?)", "allowed:", "seed")


def test_train_without_file_word_takes_a_yaml_path_or_suggests_it(write_yaml, capsys):
    rc, err = _run(capsys, ["train", write_yaml(GOOD_HEAD + "  config: {num_epoch: 3}\n")])
    assert rc == 2  # the YAML was read: its own error, not a usage error about 'file'
    _assert_one_line(err, "did you mean num_epochs")
    rc, err = _run(capsys, ["train", "experiment.txt"])
    assert rc == 2
    _assert_one_line(err, "did you mean 'rllib train file experiment.txt'?")
    assert "rllib train: error: rllib train" not in err


def test_version_names_ours_ray_and_torch(capsys):
    assert main(["--version"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("rllib-asor ") and "ray 2.60.0" in out and "torch " in out


@pytest.mark.parametrize("key", ["overlap_sampling", "drop_bootstrap_rows"])
def test_a_ppo_only_switch_on_another_algorithm_exits_2(write_yaml, capsys, key):
    path = write_yaml(
        f"x:\n  env: Pendulum-v1\n  run: SAC\n{STOP}  config: {{learner_config_dict: {{{key}: true}}}}\n"
    )
    rc, err = _run(capsys, ["train", "file", path])
    assert rc == 2
    _assert_one_line(err, f"x.config.learner_config_dict.{key}", "PPO only")


@pytest.mark.parametrize(
    ("config", "needed"),
    [
        ("{num_gpus_per_learner: 1}", "1 GPU(s) (num_gpus_per_learner: 1)"),
        ("{num_env_runners: 2, num_gpus_per_env_runner: 0.5}",
         "1 GPU(s) (num_gpus_per_env_runner: 0.5)"),
    ],
)  # fmt: skip
def test_gpus_on_a_machine_without_one_exit_2_instead_of_waiting(
    write_yaml, capsys, tmp_path, monkeypatch, config, needed
):
    monkeypatch.setattr("rllib_asor.cli.overrides.cuda_available", lambda: False)
    path = write_yaml(GOOD_HEAD + f"  config: {config}\n")
    rc, err = _run(capsys, ["train", "file", path, "--storage-path", str(tmp_path / "out")])
    assert rc == 2
    _assert_one_line(err, path, "x.config", needed, "torch sees no CUDA device",
                     "allowed on this machine: num_gpus_per_learner: 0", "--test", "--address")  # fmt: skip
    assert not (tmp_path / "out").exists()  # nothing started, nothing written
    assert _run(capsys, ["train", "file", path, "--dry-run"])[0] == 0  # where it runs decides
