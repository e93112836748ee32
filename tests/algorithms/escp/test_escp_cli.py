"""`run: ESCP` from YAML: the `escp:` block, its one-line errors, the tuned examples."""

from __future__ import annotations

from pathlib import Path

import pytest

from rllib_asor.cli import experiment
from rllib_asor.cli.main import main

EXAMPLES = Path(__file__).resolve().parents[3] / "tuned_examples" / "mujoco"


def _yaml(tmp_path: Path, run: str, block: str) -> str:
    path = tmp_path / "exp.yaml"
    path.write_text(
        f"x:\n  env: rllib_asor/HalfCheetahShift-v0\n  run: {run}\n  stop: {{training_iteration: 2}}\n"
        f"  config:\n    env_config: {{num_tasks: 4}}\n{block}"
    )
    return str(path)


@pytest.mark.parametrize(
    ("block", "fragment"),
    [
        ("    escp: {history_len: 0}\n", "escp.history_len=0 is not allowed; expected an int ≥ 1"),
        ("    escp: {windw: 5}\n", "escp.windw is not an ESCP setting"),
        ("    escp: {kernel: {grid_search: [rbf, inner]}}\n", "escp.kernel='inner'"),
    ],
)
def test_bad_escp_block_exits_2_with_one_line(tmp_path, capsys, block, fragment):
    rc = main(["train", "file", _yaml(tmp_path, "ESCP", block)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and "Traceback" not in err
    assert "x.config.escp" in err and fragment in err


def test_escp_block_needs_run_escp(tmp_path, capsys):
    rc = main(["train", "file", _yaml(tmp_path, "SAC", "    escp: {history_len: 8}\n")])
    assert rc == 2 and "needs run: ESCP" in capsys.readouterr().err


@pytest.mark.parametrize(
    "name", ["escp-walker2d", "escp-asor-walker2d", "escp-halfcheetah", "escp-asor-halfcheetah"]
)
def test_tuned_examples_build_escp_configs(name):
    exp = experiment.load_file(str(EXAMPLES / f"{name}.yaml"))[0]
    cfg = experiment.build_algo_config(exp)
    assert type(cfg).__name__ == "EscpConfig"
    assert cfg.escp_settings["history_len"] == 16 and cfg.escp_settings["num_tasks"] == 40
    assert cfg.env_config["num_tasks"] == 40
    assert (exp.asor is not None) == ("asor" in name)
