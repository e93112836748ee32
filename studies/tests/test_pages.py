"""`make results`: every study has its README and study.toml, and the committed pages under
docs/studies/ are exactly what studies/lib/pages.py makes from the run files (not hand-kept)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from studies.lib import pages


@pytest.fixture
def copy(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The studies copied to tmp_path (the summarisers rewrite table.md and summary.json)."""
    for name in pages.studies():
        shutil.copytree(pages.STUDIES / name, tmp_path / "studies" / name,
                        ignore=shutil.ignore_patterns("*.png", "data", "ensembles", "*.partial"))
    monkeypatch.setattr(pages, "STUDIES", tmp_path / "studies")
    monkeypatch.setattr(pages, "PAGES", tmp_path / "pages")
    return tmp_path


def test_every_study_has_a_readme_a_spec_and_a_page() -> None:
    folders = sorted(p.name for p in pages.STUDIES.iterdir() if (p / "runs").is_dir())
    assert folders and folders == [n for n in pages.studies() if (pages.STUDIES / n / "runs").is_dir()]
    for name in pages.studies():
        assert (pages.STUDIES / name / "README.md").read_text().startswith("# ")
        assert (pages.ROOT / "docs" / "studies" / f"{name}.md").exists(), name


def test_the_committed_pages_are_the_generated_ones(copy: Path) -> None:
    assert pages.main([]) == 0
    for name in pages.studies():
        made = (copy / "pages" / f"{name}.md").read_text()
        committed = (pages.ROOT / "docs" / "studies" / f"{name}.md").read_text()
        assert made == committed, f"docs/studies/{name}.md is stale: run `make results`"


def test_an_unknown_study_is_refused_in_one_line(copy: Path, capsys) -> None:
    assert pages.main(["no_such_study"]) == 2
    out = capsys.readouterr().out.strip()
    assert len(out.splitlines()) == 1 and "no_such_study" in out and "race_250k" in out


def test_an_unknown_runner_names_the_key_and_the_choices(copy: Path) -> None:
    with pytest.raises(ValueError, match=r"table.runner='nope'; allowed: lava, race"):
        pages.runner_table(copy / "studies" / "race_250k", {"runner": "nope"})
