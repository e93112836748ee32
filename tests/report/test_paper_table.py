"""`rllib compare --table`: tasks as rows, methods as columns, mean ± interval over seeds, the
best mean of each row in bold, on hand-written result folders with known scores."""

from __future__ import annotations

import argparse
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
    envs, labels, cells = table_cells([folder(tmp_path)])
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
