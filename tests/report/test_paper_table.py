"""`rllib compare --table`: tasks as rows, methods as columns, mean ± interval over seeds, the
best mean of each row in bold, on hand-written result folders with known scores."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from rllib_asor.cli import compare as cli
from rllib_asor.report.stats import bootstrap_ci
from rllib_asor.report.table import render_table, table_cells
from tests.report.helpers import write_trial

SCORES = {  # env -> method -> final return per seed
    "Walker-v0": {"SAC": [10.0, 12.0, 14.0], "ESCP": [20.0, 22.0, 30.0]},
    "Cheetah-v0": {"SAC": [50.0, 52.0, 54.0], "ESCP": [40.0, 41.0, 45.0]},
}


def folder(root: Path) -> Path:
    for env, methods in SCORES.items():
        for method, returns in methods.items():
            for seed, ret in enumerate(returns):
                params = {"env": env, "seed": seed, "rllib_asor_run": method}
                write_trial(root / env, f"{method}_{seed}", params, [0.0, ret])
    return root


def parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="rllib compare")
    cli.add_arguments(parser)
    return parser.parse_args(argv)


def test_cells_hold_each_methods_seed_scores_per_task(tmp_path: Path) -> None:
    envs, labels, cells, _ = table_cells([folder(tmp_path)])
    assert envs == ["Cheetah-v0", "Walker-v0"] and labels == ["ESCP", "SAC"]
    for env, methods in SCORES.items():
        for method, returns in methods.items():
            assert sorted(cells[(env, method)]) == sorted(returns)


def test_table_bolds_the_best_mean_of_each_row_with_its_interval(tmp_path: Path) -> None:
    text = render_table(*table_cells([folder(tmp_path)]))
    lines = text.splitlines()
    assert lines[0] == "| task | ESCP | SAC |"
    lo, hi = bootstrap_ci(SCORES["Walker-v0"]["ESCP"])
    walker = next(line for line in lines if line.startswith("| Walker-v0"))
    assert f"**24 ± {(hi - lo) / 2:.3g} (n=3)**" in walker and "| 12 ± " in walker
    cheetah = next(line for line in lines if line.startswith("| Cheetah-v0"))
    assert "**52 ± " in cheetah and f"{np.mean(SCORES['Cheetah-v0']['ESCP']):.3g} ± " in cheetah
    assert cheetah.count("**") == 2  # one bold cell per row


def test_a_method_missing_on_a_task_is_a_dash(tmp_path: Path) -> None:
    folder(tmp_path)
    write_trial(tmp_path / "Walker-v0", "OSI_0", {"env": "Walker-v0", "seed": 0,
                                                   "rllib_asor_run": "OSI"}, [0.0, 5.0])  # fmt: skip
    text = render_table(*table_cells([tmp_path]))
    cheetah = next(line for line in text.splitlines() if line.startswith("| Cheetah-v0"))
    assert "| — |" in cheetah


def test_cli_table_and_its_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.run(parse([str(folder(tmp_path / "r")), "--table"])) == 0
    assert capsys.readouterr().out.startswith("| task | ESCP | SAC |")
    (tmp_path / "empty").mkdir()
    assert cli.run(parse([str(tmp_path / "empty"), "--table"])) == 2
    assert "rllib compare: error: no trial results (result.json) found" in capsys.readouterr().err


def maple_trial(root: Path, name: str, params: dict, evaluation: dict[str, float]) -> None:
    """A MAPLE-family trial as `rllib train` writes it: no env runner returns, its own
    evaluation under `evaluation/<dynamics>/...` and `evaluation/mean/...`."""
    tdir = root / name
    tdir.mkdir(parents=True)
    (tdir / "params.json").write_text(json.dumps(params))
    rows = [{"training_iteration": i + 1, "evaluation": {"mean": {k: v + i for k, v in
             evaluation.items()}}} for i in range(2)]  # fmt: skip
    (tdir / "result.json").write_text("".join(json.dumps(r) + "\n" for r in rows))


def test_offline_methods_are_scored_by_their_own_evaluation_and_dara_is_a_method(tmp_path):
    env, data = "rllib_asor/HopperShift-v0", "/tmp/stand-in-{}/hopper/original/medium"
    for seed in range(2):  # each experiment its own stand-in data, as `--test` makes it
        maple = {"env": env, "seed": seed, "rllib_asor_run": "MAPLE", "input": [data.format(1)]}
        maple_trial(tmp_path / "maple", f"m{seed}", maple, {"return_mean": 10.0 + seed})
        dara = {**maple, "input": [data.format(2)], "dara_settings": {"eta": 0.1}}
        maple_trial(tmp_path / "dara", f"d{seed}", dara, {"return_mean": 20.0 + seed})
        mopo = {**maple, "rllib_asor_run": "MOPO", "input": [data.format(3)]}
        maple_trial(tmp_path / "mopo", f"o{seed}", mopo,
                    {"return_mean": 5.0, "normalized_score": 30.0 + seed})  # fmt: skip
        cql = {"env": env, "seed": seed, "rllib_asor_run": "CQL", "input": [data.format(4)]}
        maple_trial(tmp_path / "cql", f"c{seed}", cql, {})  # records no return at all
    envs, labels, cells, sources = table_cells([tmp_path])
    assert labels == ["CQL", "MAPLE", "MAPLE+DARA", "MOPO"]  # not split by the data's path
    assert sorted(cells[(env, "MAPLE")]) == [11.0, 12.0]  # the last iteration's value
    assert sorted(cells[(env, "MAPLE+DARA")]) == [21.0, 22.0]
    assert sorted(cells[(env, "MOPO")]) == [31.0, 32.0]  # the normalised score first
    assert cells[(env, "CQL")] == [] and sources[(env, "CQL")] == "no score recorded"
    assert "evaluation/mean/return_mean" in sources[(env, "MAPLE")]
    assert "evaluation/mean/normalized_score" in sources[(env, "MOPO")]
    text = render_table(envs, labels, cells, sources)
    row = next(line for line in text.splitlines() if line.startswith(f"| {env}"))
    assert row.startswith(f"| {env} | — | 11.5 ± ") and "**31.5 ± " in row
    assert "- MAPLE, MAPLE+DARA: return of its own evaluation" in text


def test_a_method_with_rllib_evaluation_keeps_it_beside_a_self_evaluating_one(tmp_path):
    env = "Walker-v0"
    for seed in range(2):
        params = {"env": env, "seed": seed, "rllib_asor_run": "SAC"}
        write_trial(tmp_path, f"SAC_{seed}", params, [0.0, 99.0], eval_returns=[0.0, 7.0])
        maple = {"env": env, "seed": seed, "rllib_asor_run": "MAPLE"}
        maple_trial(tmp_path, f"MAPLE_{seed}", maple, {"return_mean": 3.0})
    _, _, cells, sources = table_cells([tmp_path])
    # the evaluation SAC has, never its training returns because MAPLE lacks RLlib's evaluation
    assert cells[(env, "SAC")] == [7.0, 7.0]
    assert "evaluation/env_runners/episode_return_mean" in sources[(env, "SAC")]
    assert cells[(env, "MAPLE")] == [4.0, 4.0]
