"""`rllib quickstart --test` (`make smoke`): the whole `make train` pipeline on a tiny budget."""

from __future__ import annotations

import json

import imageio.v2 as imageio

from tests.cli.test_e2e import run_cli


def test_quickstart_smoke_trains_evaluates_reports_and_records(tmp_path, cli_ray):
    res = run_cli(["quickstart", "--test", "--episodes", "1", "--storage-path", str(tmp_path)])
    assert res.rc == 0, res.err[-3000:]
    report = tmp_path / "race-quickstart-test" / "report"
    evaluation = json.loads((report / "race_eval.json").read_text())
    assert sorted(evaluation["per_map"], key=int) == [str(m) for m in range(10)]
    assert len(evaluation["episodes"]) == 10  # one unseen course per map
    assert {seed for _, seed, _ in evaluation["episodes"]} == {10_000}
    assert 0.0 <= evaluation["mean"]["success"] <= 1.0
    frames = imageio.mimread(report / "racer.gif")
    assert len(frames) > 10 and frames[0].ndim == 3
    text = (report / "report.md").read_text()
    assert text.startswith("#") and "## Evaluation on unseen courses" in text
    assert f"| mean | {evaluation['mean']['success']:.3f} |" in text
    assert oct((report / "report.md").stat().st_mode & 0o777) != oct(0o600)  # not mkstemp's mode
    assert list(report.glob("curves_*.png"))
    lines = res.out.strip().splitlines()
    # Every file the summary names exists; the success rate is the last line.
    for line in lines:
        if line.startswith("  ") and " /" in line and "checkpoint=" not in line:
            path = line.split(maxsplit=1)[1].split(" (")[0]
            assert (tmp_path / path).exists() or __import__("os").path.exists(path), line
    assert lines[-1].startswith("rllib quickstart: success rate ")
    assert f"{evaluation['mean']['success']:.2f}" in lines[-1]


def test_quickstart_rejects_a_file_that_is_not_the_race(tmp_path, write_yaml, cli_ray):
    res = run_cli(["quickstart", "--file", str(tmp_path / "missing.yaml")])
    assert res.rc == 2 and "missing.yaml" in res.err and "not found" in res.err
    res = run_cli(["quickstart", "--episodes", "0"])
    assert res.rc == 2 and "--episodes" in res.err
    lava = write_yaml("lava:\n  env: rllib_asor/LavaWorld-v0\n  run: PPO\n")
    res = run_cli(["quickstart", "--file", lava, "--storage-path", str(tmp_path)])
    assert res.rc == 2 and "is not the race" in res.err
    assert not (tmp_path / "lava").exists()  # refused before training
