"""benchmarks/maple_speed.py's ensemble part alone: it must run where ray is not installed
(a GPU machine with only torch), measure all three ways of training the ensemble and write
them out."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def test_the_ensemble_part_runs_without_importing_ray(tmp_path: Path) -> None:
    code = (
        "import sys\n"
        "from benchmarks.maple_speed import main\n"
        f"main(['--parts', 'ensemble', '--rounds', '2', '--ensemble-steps', '2',"
        f" '--ensemble-rows', '16', '--out', {str(tmp_path)!r}])\n"
        "assert not [m for m in sys.modules if m == 'ray' or m.startswith('ray.')], 'ray imported'\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 0, out.stderr[-2000:]
    res = json.loads((tmp_path / "maple_speed.json").read_text())
    assert "learners" not in res
    e = res["ensemble"]["16"]
    assert e["device"] == "cpu"
    assert set(e["samples_per_s"]) == {"batched", "loop_forward", "independent"}
    assert all(r > 0 for r in e["samples_per_s"].values())
    assert all(len(v) == 2 for v in e["per_round"].values())
    assert "| 16 |" in out.stdout and "Learner" not in out.stdout


def test_an_unusable_device_is_refused_with_one_line(capsys) -> None:
    from benchmarks.maple_speed import main

    with pytest.raises(SystemExit) as exit_:
        main(["--parts", "ensemble", "--device", "nodevice"])
    assert exit_.value.code == 2
    assert "--device 'nodevice' is not usable here" in capsys.readouterr().err
