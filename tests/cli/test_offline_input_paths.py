"""Offline `input` paths in a YAML are resolved against the launch directory."""

import os

import pytest

from rllib_asor.cli.errors import UsageError
from rllib_asor.cli.experiment import check_offline_input, parse_experiment


def _input_of(value):
    spec = {"env": "Pendulum-v1", "run": "CQL", "config": {"input": value}}
    return parse_experiment("x", spec, "x.yaml").config["input"]


def test_relative_input_paths_become_absolute(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "data/offline/hopper").mkdir(parents=True)
    (tmp_path / "a").mkdir()
    assert _input_of("data/offline/hopper") == os.path.join(str(tmp_path), "data/offline/hopper")
    assert _input_of(["a", "s3://bucket/b"]) == [os.path.join(str(tmp_path), "a"), "s3://bucket/b"]


def test_missing_dataset_fails_before_ray_and_names_make_datasets(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    spec = {
        "env": "Pendulum-v1",
        "run": "CQL",
        "config": {"input": ["data/offline/hopper/original/medium"]},
    }
    exp = parse_experiment("x", spec, "x.yaml")
    with pytest.raises(
        UsageError, match=r"x\.config\.input: offline input .*does not exist.*make datasets"
    ):
        check_offline_input(exp)


def test_sampler_and_uris_are_kept():
    assert _input_of("sampler") == "sampler"
    assert _input_of("gs://bucket/data") == "gs://bucket/data"


def test_offline_runs_reserve_cpus_for_ray_data():
    """A local Ray sized for the trial alone left Ray Data's readers waiting forever (2 CPUs:
    the trial took 1, Ray Data asked for 3)."""
    from ray.rllib.algorithms.cql import CQLConfig
    from ray.rllib.algorithms.ppo import PPOConfig

    from rllib_asor.cli.experiment import offline_data_cpus, required_cpus

    online = PPOConfig().env_runners(num_env_runners=0)
    assert offline_data_cpus(online) == 0 and required_cpus(online) == 1
    offline = CQLConfig().env_runners(num_env_runners=0).offline_data(input_=["/data/x"])
    assert offline_data_cpus(offline) == 3  # one read task + 2 OfflinePreLearner actors
    assert required_cpus(offline) == 4
    offline.offline_data(map_batches_kwargs={"concurrency": 1, "num_cpus": 0.5})
    assert offline_data_cpus(offline) == 1.5


def test_offline_test_run_without_data_builds_tiny_stand_ins(tmp_path, monkeypatch, cli_ray):
    """`--test` on a fresh clone (no `make datasets`): exit 0 on stand-in data, said up front."""
    from tests.cli.test_e2e import REPO, run_cli

    monkeypatch.chdir(tmp_path)  # no data/offline here
    res = run_cli(
        [
            "train",
            "file",
            str(REPO / "tuned_examples/offline/cql-asor-hopper.yaml"),
            "--test",
            "--storage-path",
            str(tmp_path / "runs"),
        ]
    )
    assert res.rc == 0, res.err[-3000:]
    assert "offline dataset(s) missing" in res.out and "make datasets" in res.err
    assert "1 trial(s), 0 errored" in res.out
    res = run_cli(["train", "file", str(REPO / "tuned_examples/offline/cql-asor-hopper.yaml")])
    assert res.rc == 2 and "make datasets" in res.err  # a real run still refuses
