"""What a file gets wrong is said at once and plainly: a missing `stop:` is
refused unless `--test` or `--stop` supplies one, every problem of a file is one line of its own
in one report, and the `run:` names allowed are the registry's (RLlib's and ours)."""

from __future__ import annotations

import pytest

from rllib_asor.cli.main import main
from rllib_asor.cli.schema import run_names  # the names `rllib schema` takes

NO_STOP = "x:\n  env: CartPole-v1\n  run: PPO\n  config: {lr: 0.001}\n"
STOP = "  stop: {training_iteration: 2}\n"


def _error_lines(capsys, argv: list[str]) -> list[str]:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert all(line.startswith("rllib ") and ": error: " in line for line in lines), err
    return lines


@pytest.mark.parametrize("stop", ["", "  stop: {}\n", "  stop:\n"])
def test_a_file_without_a_stop_is_refused_naming_what_is_allowed(write_yaml, capsys, stop):
    path = write_yaml(NO_STOP + stop)
    [line] = _error_lines(capsys, ["train", "file", path, "--dry-run"])
    for fragment in (path, "x.stop", "missing", "would train forever",
                     "stop: {num_env_steps_sampled_lifetime: 100000}", "--stop KEY=VALUE"):  # fmt: skip
        assert fragment in line, line


def test_flags_without_a_stop_are_refused_too(capsys):
    argv = ["train", "--run", "PPO", "--env", "CartPole-v1", "--dry-run"]
    [line] = _error_lines(capsys, argv)
    assert "stop" in line and "--stop KEY=VALUE" in line, line
    assert main([*argv, "--stop", "training_iteration=1"]) == 0


@pytest.mark.parametrize("extra", [["--test"], ["--stop", "training_iteration=3"]])
def test_test_or_a_stop_flag_supplies_the_stop(write_yaml, capsys, extra):
    assert main(["train", "file", write_yaml(NO_STOP), "--dry-run", *extra]) == 0, (
        capsys.readouterr().err
    )


def test_rllib_ab_refuses_a_file_without_a_stop_before_ray_starts(write_yaml, capsys, tmp_path):
    path = write_yaml(NO_STOP.replace("{lr: 0.001}", "{lr: 0.001, asor: {seed: 0}}"))
    argv = ["ab", path, "--seeds", "2", "--storage-path", str(tmp_path / "results")]
    [line] = _error_lines(capsys, argv)
    assert "x.stop" in line and "--stop KEY=VALUE" in line, line


def test_every_problem_of_a_file_is_reported_at_once_one_line_each(write_yaml, capsys):
    path = write_yaml(
        "x:\n  env: CartPole-v1\n  run: PPO\n"
        "  stop: {num_env_steps_sampled_lifetim: 1000}\n"
        "  config: {num_sgd_iters: 3, gamma: high, asor: {rho_value: 1.5}}\n"
    )
    lines = _error_lines(capsys, ["train", "file", path, "--dry-run"])
    keys = ("x.config.num_sgd_iters", "x.config.gamma", "x.config.asor",
            "x.stop.num_env_steps_sampled_lifetim")  # fmt: skip
    for key in keys:
        assert sum(key + ":" in line for line in lines) == 1, (key, lines)
    assert len(lines) == len(keys), lines


def test_every_experiment_and_every_entry_key_is_reported(write_yaml, capsys):
    path = write_yaml(
        "a:\n  env: CartPole-v1\n  run: PPO\n  stopp: {}\n  num_samples: 0\n" + STOP
        + "b:\n  env: CartPole-v1\n  run: PPOO\n" + STOP
        + "c:\n  env: CartPole-v1\n  run: PPO\n" + STOP + "  config: {lr: fast}\n"
    )
    lines = _error_lines(capsys, ["train", "file", path, "--dry-run"])
    for key in ("a.stopp:", "a.num_samples:", "b.run:", "c.config.lr:"):
        assert sum(key in line for line in lines) == 1, (key, lines)
    assert len(lines) == 4, lines


def test_old_keys_with_bad_values_are_all_reported(write_yaml, capsys):
    path = write_yaml(
        "x:\n  env: CartPole-v1\n  run: PPO\n" + STOP
        + "  config: {framework: jax, observation_filter: Fancy, model: {no_such: 1}}\n"
    )
    lines = _error_lines(capsys, ["train", "file", path, "--dry-run"])
    for key in ("x.config.framework:", "x.config.observation_filter:", "x.config.model.no_such:"):
        assert sum(key in line for line in lines) == 1, (key, lines)


def test_an_unknown_run_lists_every_name_the_schema_takes(write_yaml, capsys):
    [line] = _error_lines(
        capsys, ["train", "file", write_yaml("x:\n  env: CartPole-v1\n  run: PPOO\n" + STOP)]
    )
    listed = line.split("allowed: ", 1)[1].split(", ")
    assert listed == run_names()
    assert {"FastSAC", "ESCP", "MAPLE", "MOPO", "OSI", "CaDM", "PPO", "SAC"} <= set(listed)


def test_rllib_ab_reports_every_problem_of_its_file_at_once(write_yaml, capsys, tmp_path):
    path = write_yaml(
        "x:\n  env: CartPole-v1\n  run: PPO\n"
        "  config: {gamma: high, asor: {seed: 0}}\n"
    )
    argv = ["ab", path, "--seeds", "2", "--storage-path", str(tmp_path / "results")]
    lines = _error_lines(capsys, argv)
    assert any("x.config.gamma" in line for line in lines), lines
    assert any("x.stop" in line for line in lines), lines
