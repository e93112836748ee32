"""The supported Ray range is stated once per place and agrees everywhere: pyproject.toml's
requirement, rllib_asor/ray_compat.py's tested releases, the Makefile's `make compat` releases,
the README and docs/testing.md. No Ray is imported here (`make compat` checks the releases)."""

from __future__ import annotations

import os
import re
import subprocess
import tomllib
from pathlib import Path

import pytest
from packaging.requirements import Requirement

from rllib_asor import ray_compat as compat

ROOT = Path(__file__).resolve().parents[1]

# Ray's releases around the range (PyPI); the range must admit the tested ones and no other.
RELEASES = ("2.57.0", "2.58.0", "2.58.1", "2.59.0", "2.60.0", "2.61.0")


def ray_requirement() -> Requirement:
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    (req,) = [Requirement(d) for d in deps if Requirement(d).name == "ray"]
    return req


def make_releases() -> tuple[str, ...]:
    (line,) = re.findall(r"^RAY_RELEASES\s*:=(.*)$", (ROOT / "Makefile").read_text(), re.M)
    return tuple(line.split())


def test_pyproject_requires_the_stated_range():
    assert str(ray_requirement()) == str(Requirement(compat.RAY_REQUIREMENT))
    assert ray_requirement().extras == {"rllib", "tune"}


def test_the_range_admits_the_tested_releases_and_no_other():
    admitted = tuple(v for v in RELEASES if ray_requirement().specifier.contains(v))
    assert admitted == compat.RAY_TESTED
    as_tuple = [tuple(map(int, v.split("."))) for v in compat.RAY_TESTED]
    assert as_tuple == sorted(as_tuple)


def test_make_compat_offers_the_tested_releases():
    assert make_releases() == compat.RAY_TESTED


@pytest.mark.parametrize("doc", ["README.md", "docs/testing.md"])
def test_the_docs_state_the_tested_range(doc):
    text = (ROOT / doc).read_text()
    assert compat.RAY_REQUIREMENT.split("]", 1)[1] in text
    assert all(v in text for v in compat.RAY_TESTED), doc


def make(*args: str) -> subprocess.CompletedProcess:
    """`make -n ARGS` in the repository, free of the flags of a `make test` that runs us."""
    env = {k: v for k, v in os.environ.items() if k not in ("MAKEFLAGS", "MFLAGS", "MAKELEVEL")}
    return subprocess.run(
        ["make", "--no-print-directory", "-n", *args],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip


@pytest.mark.parametrize("ray", ["", "2.57.0", "2.58.1 2.59.0", "latest"])
def test_make_compat_refuses_what_is_no_tested_release_in_one_line(ray):
    done = make("compat", f"RAY={ray}")
    assert done.returncode != 0 and done.stdout == ""
    (line,) = done.stderr.strip().splitlines()
    assert f"RAY='{ray}' is not" in line and all(v in line for v in compat.RAY_TESTED)


def test_make_compat_builds_its_own_venv_and_runs_the_compat_tests():
    release = compat.RAY_TESTED[0]
    done = make("compat", f"RAY={release}", "-B")  # -B: as if the venv were not built yet
    assert done.returncode == 0, done.stderr
    lines = done.stdout.replace("\\\n", " ").splitlines()
    venv = f".venv-ray-{release}"
    assert f"python3 -m venv {venv}" in lines[0]
    (torch,) = [ln for ln in lines if '"torch==' in ln]
    assert torch.startswith(f"{venv}/bin/python -m pip") and '"torch==2.13.0"' in torch
    (pkg,) = [ln for ln in lines if " -e " in ln]
    assert f'{venv}/bin/python -m pip install -q -e ".[test]" "ray[rllib,tune]=={release}"' in pkg
    (run,) = [ln for ln in lines if " -m pytest " in ln]
    assert run.startswith(f"{venv}/bin/python -m pytest ")
    assert run.split()[-4:] == [
        "tests/rllib", "tests/algorithms/test_fast_sac.py", "tests/algorithms/escp",
        "tests/cli/test_e2e.py",
    ]  # fmt: skip
    assert lines.index(pkg) < lines.index(run)
