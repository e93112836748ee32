"""The documentation site (`make docs`): `mkdocs build --strict` of mkdocs.yml succeeds, the API
reference pages hold what the docstrings say, and the strict settings do turn a broken link
into a failed build."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
API_PAGES = ("index", "with_asor", "asor_config", "escp", "maple", "envs", "game_env", "cli")


def _mkdocs_build(config: Path, site: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(config), "-d", str(site)],
        cwd=config.parent,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_the_site_builds_strict_with_every_public_name_documented(tmp_path: Path) -> None:
    from rllib_asor.asor.config import AsorConfig
    from rllib_asor.cli.main import build_parser

    site = tmp_path / "site"
    proc = _mkdocs_build(ROOT / "mkdocs.yml", site)
    assert proc.returncode == 0, proc.stderr[-4000:]

    pages = {name: (site / "api" / name / "index.html").read_text() for name in API_PAGES[1:]}
    assert (site / "api" / "index.html").exists() and (site / "index.html").exists()
    assert "rllib_asor.rllib.wiring.with_asor" in pages["with_asor"]
    assert "Raises ValueError" in pages["with_asor"]  # the docstring, not only the signature
    for name in AsorConfig.model_fields:  # every setting with its own entry
        assert f'id="rllib_asor.asor.config.AsorConfig.{name}"' in pages["asor_config"]
    assert 'id="rllib_asor.algorithms.escp.config.EscpConfig"' in pages["escp"]
    assert 'id="rllib_asor.algorithms.sac.config.FastSACConfig"' in pages["with_asor"]
    for name in ("MapleConfig", "MopoConfig"):
        assert f'id="rllib_asor.algorithms.maple.maple.{name}"' in pages["maple"]
    for name in ("lava.LavaWorldEnv", "mujoco_shift.MujocoShiftEnv", "traffic.HighwayDensityEnv"):
        assert f'id="rllib_asor.envs.{name}"' in pages["envs"]
    for name in ("env.ObstacleRaceEnv", "parallel.RaceParallelEnv"):
        assert f'id="game_env.{name}"' in pages["game_env"]
    subcommands = next(
        a.choices for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)
    )
    for command in subcommands:  # the hook's --help sections, one per subcommand
        assert f"usage: rllib {command}" in pages["cli"], command


def test_a_broken_link_fails_the_strict_build(tmp_path: Path) -> None:
    ours = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "index.md").write_text("# Home\n\nSee [the guide](guide.md).\n")
    config = {"site_name": "t", "docs_dir": "docs", "strict": ours["strict"]}
    config["validation"] = ours.get("validation", {})
    (tmp_path / "mkdocs.yml").write_text(yaml.safe_dump(config))
    proc = _mkdocs_build(tmp_path / "mkdocs.yml", tmp_path / "site")
    assert proc.returncode != 0
    assert "guide.md" in proc.stderr
