"""benchmarks.mutation.verdicts: mutmut's verdicts survive a fresh checkout (no mutmut run)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks.mutation import run, verdicts

META = {
    "exit_code_by_key": {"pkg.mod.x_f__mutmut_1": 1, "pkg.mod.x_f__mutmut_2": 0,
                         "pkg.mod.x_g__mutmut_1": None},
    "hash_by_function_name": {"x_f": "aa", "x_g": "bb"},
    "type_check_error_by_key": {},
    "durations_by_key": {"pkg.mod.x_f__mutmut_1": 0.5},
    "estimated_durations_by_key": {},
}  # fmt: skip


def build_with_meta(root: Path) -> Path:
    meta = root / "mutants" / "pkg" / "mod.py.meta"
    meta.parent.mkdir(parents=True)
    meta.write_text(json.dumps(META))
    return root


def test_a_fresh_build_gets_the_saved_verdicts_back(tmp_path: Path) -> None:
    records = tmp_path / "records"
    assert verdicts.save("glue", build_with_meta(tmp_path / "old"), records) == 2
    fresh = tmp_path / "new"
    assert verdicts.restore("glue", fresh, records) == 2
    meta = json.loads((fresh / "mutants" / "pkg" / "mod.py.meta").read_text())
    assert meta["exit_code_by_key"] == META["exit_code_by_key"]
    assert meta["hash_by_function_name"] == META["hash_by_function_name"]
    assert meta["durations_by_key"] == {}  # mutmut's to measure again
    # what run.py's summary reads from it: one killed, one survivor, one not yet tested
    summary = run.summarise("glue", fresh, {"only_mutate": ["pkg/*.py"]}, {})
    assert (summary["killed"], summary["survived"], summary["not_checked"]) == (1, 1, 1)


def test_a_build_keeps_its_own_verdicts_and_an_empty_build_writes_no_record(
    tmp_path: Path,
) -> None:
    records = tmp_path / "records"
    verdicts.save("glue", build_with_meta(tmp_path / "old"), records)
    own = build_with_meta(tmp_path / "own")
    (own / "mutants" / "pkg" / "mod.py.meta").write_text(
        json.dumps({**META, "exit_code_by_key": {"pkg.mod.x_f__mutmut_1": 0}})
    )
    assert verdicts.restore("glue", own, records) == 0
    meta = json.loads((own / "mutants" / "pkg" / "mod.py.meta").read_text())
    assert meta["exit_code_by_key"] == {"pkg.mod.x_f__mutmut_1": 0}
    assert verdicts.save("asor", tmp_path / "nothing", records) == 0
    assert not (records / "asor.json").exists()
    assert verdicts.restore("asor", tmp_path / "nothing", records) == 0


def test_a_record_of_another_package_is_refused(tmp_path: Path) -> None:
    records = tmp_path / "records"
    verdicts.save("glue", build_with_meta(tmp_path / "old"), records)
    (records / "glue.json").rename(records / "asor.json")
    with pytest.raises(ValueError, match="'glue', not 'asor'"):
        verdicts.restore("asor", tmp_path / "new", records)


def test_a_rerun_forgets_timeouts_and_keeps_every_other_verdict(tmp_path: Path) -> None:
    build = build_with_meta(tmp_path)
    meta = build / "mutants" / "pkg" / "mod.py.meta"
    data = json.loads(meta.read_text())
    data["exit_code_by_key"]["pkg.mod.x_g__mutmut_1"] = -24  # mutmut's limit: a timeout
    meta.write_text(json.dumps(data))
    pkg = {"only_mutate": ["pkg/*.py"]}
    assert run.summarise("glue", build, pkg, {})["killed"] == 2  # a timeout counts as killed
    run.forget_timeouts(build)
    codes = json.loads(meta.read_text())["exit_code_by_key"]
    assert codes == {"pkg.mod.x_f__mutmut_1": 1, "pkg.mod.x_f__mutmut_2": 0,
                     "pkg.mod.x_g__mutmut_1": None}  # fmt: skip


def test_the_sandbox_config_carries_the_timeout_constant(tmp_path: Path) -> None:
    import tomllib

    defaults, packages = run.load_packages()
    run.write_config(tmp_path, defaults, packages["glue"])
    mutmut = tomllib.loads((tmp_path / "pyproject.toml").read_text())["tool"]["mutmut"]
    assert mutmut["timeout_constant"] == defaults["timeout_constant"] > 1.0  # mutmut's own: 1
    run.write_config(tmp_path, defaults, {**packages["glue"], "timeout_constant": 12})
    assert "timeout_constant = 12.0" in (tmp_path / "pyproject.toml").read_text()
