"""studies.lib.race_learning's `--model-config`: validated JSON that reaches the race network."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from studies.lib.common import runs_made_otherwise, write_json
from studies.lib.race_learning import main, race_config

SMALL = '{"cnn_channels": [8, 16], "attn_token_size": 8}'


def test_model_config_reaches_the_module_spec() -> None:
    args = argparse.Namespace(
        steps=1000, batch=256, epochs=1, envs=1, max_episode_steps=50, model_config=SMALL
    )
    spec = race_config(0, None, args).rl_module_spec
    assert spec.model_config == {"cnn_channels": [8, 16], "attn_token_size": 8}


@pytest.mark.parametrize(
    ("text", "named"),
    [
        ("{not json", "Expecting property name"),
        ("[8, 16]", "a JSON object is needed"),
        ('{"cnn_channel": [8]}', "unknown keys ['cnn_channel']"),
        ('{"cnn_channels": [8, 0]}', "a list of positive integers"),
    ],
)
def test_bad_model_config_is_a_usage_error(
    text: str, named: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["--model-config", text, "--summarize-only", "--out", str(tmp_path)])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "--model-config" in err and named in err


def test_rerun_with_other_settings_into_the_same_folder_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_json(
        tmp_path / "runs" / "ppo-0.json", {"method": "ppo", "seed": 0, "sampling": "overlap"}
    )
    with pytest.raises(SystemExit) as exit_info:
        main(["--methods", "ppo", "--seeds", "1", "--out", str(tmp_path)])
    assert exit_info.value.code == 2
    assert "ppo-0.json (sampling='overlap')" in capsys.readouterr().err


def test_runs_made_otherwise_compares_recorded_keys_and_defaults(tmp_path: Path) -> None:
    write_json(tmp_path / "runs" / "a-0.json", {"layout": "E"})
    write_json(tmp_path / "runs" / "a-1.json", {})  # written before the key was recorded
    write_json(tmp_path / "runs" / "a-2.json", {"layout": "B"})
    assert runs_made_otherwise(tmp_path, ["a"], range(4), {"layout": "B"}) == [
        "a-0.json (layout='E')"
    ]
    with_default = runs_made_otherwise(tmp_path, ["a"], range(4), {"layout": "E"}, {"layout": "B"})
    assert with_default == ["a-1.json (layout='B')", "a-2.json (layout='B')"]


def test_the_reference_racers_run_through_the_races_evaluation() -> None:
    """The scripted racer reads each evaluation env's simulator (`needs_envs`); on map 0 it
    collects goal reward in 300 steps where the random policy collects none."""
    from rllib_asor.race.evaluation import evaluate
    from studies.lib.race_learning import random_policy, scripted_policy

    scripted = evaluate(scripted_policy, 1, 300, maps=[0], needs_envs=True)
    random = evaluate(random_policy(), 1, 300, maps=[0])
    assert scripted["per_map"][0]["goal_reward"] > random["per_map"][0]["goal_reward"]
