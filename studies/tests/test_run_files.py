"""Run files: written compressed and atomically, read in either form, compressed losslessly."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import pytest

from studies.lib import run_files
from studies.lib.common import run_if_missing, runs_made_otherwise
from studies.lib.compare import load_metric_by_seed


def test_a_written_run_reads_back_and_equal_records_give_equal_bytes(tmp_path: Path) -> None:
    record = {"method": "ppo", "seed": 3, "curve": [0.1, float("nan")], "eval": {"x": 1.5}}
    a, b = run_files.run_file(tmp_path / "a", "ppo-3"), run_files.run_file(tmp_path / "b", "ppo-3")
    run_files.write_run(a, record)
    run_files.write_run(b, record)
    assert a.name == "ppo-3.json.gz" and a.read_bytes() == b.read_bytes()
    back = run_files.read_run(a)
    assert back["eval"] == {"x": 1.5} and back["curve"][0] == 0.1 and back["curve"][1] != 0.1
    assert json.loads(gzip.decompress(a.read_bytes()))["seed"] == 3  # plain gzip: zcat reads it
    assert [p.name for p in (tmp_path / "a").iterdir()] == ["ppo-3.json.gz"]  # no temp left


def test_both_forms_are_read_in_name_order_and_a_run_held_twice_is_refused(tmp_path: Path) -> None:
    run_files.write_run(run_files.run_file(tmp_path, "b-1"), {"method": "b", "seed": 1})
    (tmp_path / "a-0.json").write_text(json.dumps({"method": "a", "seed": 0}))
    (tmp_path / "notes.txt").write_text("not a run")
    assert [r["method"] for r in run_files.read_runs(tmp_path)] == ["a", "b"]
    assert [p.name for p in run_files.run_paths(tmp_path, "b-*")] == ["b-1.json.gz"]
    assert run_files.existing(run_files.run_file(tmp_path, "a-0")) == tmp_path / "a-0.json"
    assert run_files.existing(run_files.run_file(tmp_path, "c-0")) is None
    (tmp_path / "b-1.json").write_text(json.dumps({"method": "b", "seed": 1}))
    with pytest.raises(SystemExit, match="'b-1' is held twice"):
        run_files.read_runs(tmp_path)


def test_compress_keeps_the_text_and_the_readers_see_the_same_runs(tmp_path: Path) -> None:
    runs = tmp_path / "study" / "runs"
    runs.mkdir(parents=True)
    texts = {}
    for seed in range(3):
        text = json.dumps({"method": "ppo", "seed": seed, "eval": {"s": seed / 4}}, indent=1)
        (runs / f"ppo-{seed}.json").write_text(text)
        texts[seed] = text.encode()
    (tmp_path / "study" / "summary.json").write_text("{}")  # not a run file: left alone
    before = load_metric_by_seed([tmp_path / "study"], "eval.s")
    written = run_files.compress(tmp_path)
    assert sorted(p.name for p in written) == [f"ppo-{s}.json.gz" for s in range(3)]
    assert sorted(p.name for p in runs.iterdir()) == [f"ppo-{s}.json.gz" for s in range(3)]
    assert all(gzip.decompress((runs / f"ppo-{s}.json.gz").read_bytes()) == texts[s] for s in texts)
    assert (
        load_metric_by_seed([tmp_path / "study"], "eval.s")
        == before
        == {"ppo": {0: 0.0, 1: 0.25, 2: 0.5}}
    )
    assert (tmp_path / "study" / "summary.json").exists()


def test_a_finished_run_in_either_form_is_not_run_again(tmp_path: Path) -> None:
    calls = []

    def run() -> dict:
        calls.append(1)
        return {"eval": 1.0, "wall_s": 2.0}

    (tmp_path / "old-0.json").write_text(json.dumps({"eval": 0.0}))
    run_if_missing(run_files.run_file(tmp_path, "old-0"), "old 0", run)
    assert calls == []
    path = run_files.run_file(tmp_path, "new-0")
    run_if_missing(path, "new 0", run)
    run_if_missing(path, "new 0", run)
    assert calls == [1] and run_files.read_run(path)["eval"] == 1.0


def test_settings_are_checked_in_both_forms(tmp_path: Path) -> None:
    run_files.write_run(run_files.run_file(tmp_path / "runs", "a-0"), {"layout": "E"})
    (tmp_path / "runs" / "a-1.json").write_text(json.dumps({"layout": "E"}))
    assert runs_made_otherwise(tmp_path, ["a"], range(3), {"layout": "B"}) == [
        "a-0.json.gz (layout='E')",
        "a-1.json (layout='E')",
    ]


def test_the_command_names_a_missing_folder(tmp_path: Path, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        run_files.main(["compress", str(tmp_path / "nope")])
    assert exc.value.code == 2 and "no such folder" in capsys.readouterr().err
