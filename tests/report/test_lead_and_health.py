"""`rllib report` leads with the paired answer (or says its numbers are unpaired), and
`rllib report` and `rllib compare` name an inert ASOR in one line."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from rllib_asor.cli import compare as compare_cli
from rllib_asor.cli import report as report_cli
from rllib_asor.report.compare import compare, render_text
from rllib_asor.report.lead import paired_lead
from rllib_asor.report.render import write_report
from tests.report.helpers import write_trial
from tests.report.test_compare import ENV, ab_folder

AT_CHANCE = {"js_estimate": 0.002, "disc_acc": 0.5, "active": 1.0, "bonus_share": 0.01,
             "critic_ev": 0.0007, "archive_states": 4096.0}  # fmt: skip


def add_asor_rows(root: Path, asor: dict[str, float], iterations: int = 12) -> None:
    """Give every ASOR trial under `root` `iterations` rows reporting `asor`."""
    for rj in root.rglob("result.json"):
        if "asor" not in json.loads((rj.parent / "params.json").read_text()):
            continue
        rows = [json.loads(line) for line in rj.read_text().splitlines()]
        last = rows[-1]
        rows = [
            dict(last, training_iteration=i + 1, asor=asor, num_env_steps_sampled_lifetime=i + 1)
            for i in range(iterations)
        ]
        rj.write_text("".join(json.dumps(r) + "\n" for r in rows))


def _args(cli, argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    cli.add_arguments(parser)
    return parser.parse_args(argv)


def test_report_leads_with_the_paired_answer(tmp_path: Path, capsys) -> None:
    root = ab_folder(tmp_path, effect=10.0)
    lead = paired_lead(root)
    assert lead[0].startswith("Paired answer (`rllib compare ")
    assert "PPO+ASOR − PPO = +10" in lead[0] and "treatment better" in lead[0]
    report, md = write_report(root, tmp_path / "out")
    assert md.read_text().splitlines()[2] == lead[0]  # right under the title
    assert report_cli.run(_args(report_cli, [str(root), "--out", str(tmp_path / "o2")])) == 0
    assert capsys.readouterr().out.splitlines()[0] == lead[0]


def test_report_without_pairs_says_its_numbers_are_unpaired(tmp_path: Path) -> None:
    for s in range(3):
        write_trial(tmp_path / "exp", f"PPO_{s}", {"env": ENV, "seed": s}, [1.0, 2.0 + s])
    (line,) = paired_lead(tmp_path)
    assert line.startswith("Unpaired: the numbers below are training returns")
    assert f"`rllib compare {tmp_path}`" in line


def test_an_inert_asor_is_one_line_in_report_and_compare(tmp_path: Path, capsys) -> None:
    root = ab_folder(tmp_path, effect=0.0, seeds=6)
    add_asor_rows(root, AT_CHANCE)
    report, md = write_report(root, tmp_path / "out")
    (group,) = [g for g in report.groups if g.method == "PPO+ASOR"]
    assert group.asor_health.startswith(f"{ENV}: PPO+ASOR: asor inert: disc at chance in 6/6")
    assert "explained variance is 0.0007" in group.asor_health and "try: " in group.asor_health
    assert group.asor_health in md.read_text()
    assert [g.asor_health for g in report.groups if g.method == "PPO"] == [None]

    comp = compare([root])
    (res,) = comp.results
    assert res.asor_health.startswith("PPO+ASOR: asor inert: disc at chance")
    assert res.asor_health in render_text(comp)
    assert compare_cli.run(_args(compare_cli, [str(root), "--json"])) == 0
    (row,) = json.loads(capsys.readouterr().out)
    assert row["asor_health"] == res.asor_health


@pytest.mark.parametrize("asor", [dict(AT_CHANCE, js_estimate=0.3), {}])
def test_a_working_or_absent_asor_says_nothing(tmp_path: Path, asor) -> None:
    root = ab_folder(tmp_path, effect=0.0, seeds=6)
    if asor:
        add_asor_rows(root, asor)
    assert compare([root]).results[0].asor_health is None
    assert "inert" not in write_report(root, tmp_path / "out")[1].read_text()
