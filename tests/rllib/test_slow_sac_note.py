"""`with_asor(SACConfig())` wraps RLlib's own SAC Learner (~1.8 env steps/s against
FastSACConfig's ~12 on Hopper, docs/results.md): it says so once, pointing at
`rllib_asor.FastSACConfig`; configs that chose a path (the fast one, or RLlib's on purpose, as
`rllib train` records for `run: SAC`) and ASOR settings the fast path cannot run get no note."""

from __future__ import annotations

import warnings

import pytest
from ray.rllib.algorithms.sac import SACConfig

from rllib_asor import FastSACConfig, with_asor
from rllib_asor.algorithms.sac.fast import FAST_KEY
from rllib_asor.cli import experiment


def _notes(config, **settings) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with_asor(config.environment("Pendulum-v1"), **settings)
    return [str(w.message) for w in caught if "FastSACConfig" in str(w.message)]


def test_rllibs_own_sac_gets_one_line_pointing_at_fast_sac():
    [note] = _notes(SACConfig())
    assert "rllib_asor.FastSACConfig" in note and "RLlib's own SAC Learner" in note
    assert "\n" not in note


@pytest.mark.parametrize(
    "config",
    [
        FastSACConfig(),
        SACConfig().learners(learner_config_dict={FAST_KEY: False}),  # RLlib's SAC, on purpose
    ],
    ids=["fast", "opted-out"],
)
def test_a_config_that_chose_its_path_gets_no_note(config):
    assert _notes(config) == []


def test_per_dynamics_rnd_which_the_fast_path_cannot_run_gets_no_note():
    assert _notes(SACConfig(), proxy="rnd_per_dynamics") == []


def test_the_cli_run_sac_path_gets_no_note(tmp_path):
    path = tmp_path / "sac.yaml"
    path.write_text("x:\n  env: Pendulum-v1\n  run: SAC\n  stop: {training_iteration: 1}\n")
    [exp] = experiment.load_file(str(path))
    cfg = experiment.build_algo_config(exp)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with_asor(cfg)
    assert not [w for w in caught if "FastSACConfig" in str(w.message)]
