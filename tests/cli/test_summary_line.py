"""The per-trial summary `rllib train` prints at the end never says `nan`: a trial whose
episodes never finished (SAC's first iterations on a long-episode env) reads
`return_mean=n/a (no episode finished)` (hand-made Tune results, no Ray run)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from rllib_asor.cli.train import print_summary


class _Results(list):
    errors: list = []


def _summary(capsys, metrics: dict) -> str:
    exp = SimpleNamespace(name="x")
    result = SimpleNamespace(metrics=metrics, checkpoint=None, error=None)
    assert print_summary(exp, _Results([result])) == 0
    return capsys.readouterr().out


BASE = {"training_iteration": 2, "num_env_steps_sampled_lifetime": 400, "done": True}


@pytest.mark.parametrize(
    "runners", [{"episode_return_mean": float("nan")}, {}, {"episode_return_mean": None}]
)
def test_no_finished_episode_reads_n_a_never_nan(capsys, runners):
    out = _summary(capsys, dict(BASE, env_runners=runners))
    assert "return_mean=n/a (no episode finished)" in out, out
    assert "nan" not in out.lower(), out


def test_a_finished_episode_shows_its_mean(capsys):
    out = _summary(capsys, dict(BASE, env_runners={"episode_return_mean": -1234.5678}))
    assert "OK iter=2 env_steps=400 return_mean=-1234.57 " in out, out
