"""Offline `input` paths in a YAML are resolved against the launch directory."""

import os

from rllib_asor.cli.experiment import parse_experiment


def _input_of(value):
    spec = {"env": "Pendulum-v1", "run": "CQL", "config": {"input": value}}
    return parse_experiment("x", spec, "x.yaml").config["input"]


def test_relative_input_paths_become_absolute(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert _input_of("data/offline/hopper") == os.path.join(str(tmp_path), "data/offline/hopper")
    assert _input_of(["a", "s3://bucket/b"]) == [os.path.join(str(tmp_path), "a"), "s3://bucket/b"]


def test_sampler_and_uris_are_kept():
    assert _input_of("sampler") == "sampler"
    assert _input_of("gs://bucket/data") == "gs://bucket/data"
