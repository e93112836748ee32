"""`run: MAPLE` / `run: MOPO` from YAML: the `maple:` block, its validation, missing data."""

from __future__ import annotations

from pathlib import Path

import pytest

from rllib_asor.cli import experiment
from rllib_asor.cli.main import main

EXAMPLES = Path(__file__).resolve().parents[3] / "tuned_examples" / "offline"


def _yaml(tmp_path: Path, run: str, block: str, input_: str | None = None) -> str:
    data = input_ or str(tmp_path)
    path = tmp_path / "exp.yaml"
    path.write_text(
        f"x:\n  env: rllib_asor/HopperShift-v0\n  run: {run}\n  stop: {{training_iteration: 2}}\n"
        f"  config:\n    input: [{data}]\n{block}"
    )
    return str(path)


def _err(capsys, argv: list[str]) -> tuple[int, str]:
    rc = main(argv)
    return rc, capsys.readouterr().err.strip()


@pytest.mark.parametrize(
    ("block", "fragment"),
    [
        ("    maple: {horizon: 0}\n", "maple.horizon=0 is invalid: allowed an integer >= 1"),
        ("    maple: {horizn: 5}\n", "did you mean 'horizon'"),
        ("    maple: {penalty_coef: {grid_search: [0.25, -1]}}\n", "maple.penalty_coef=-1"),
    ],
)
def test_bad_maple_block_exits_2_naming_the_key(tmp_path, capsys, block, fragment):
    rc, err = _err(capsys, ["train", "file", _yaml(tmp_path, "MAPLE", block)])
    assert rc == 2 and len(err.splitlines()) == 1 and "Traceback" not in err
    assert "x.config.maple" in err and fragment in err


def test_maple_block_needs_run_maple_or_mopo(tmp_path, capsys):
    rc, err = _err(capsys, ["train", "file", _yaml(tmp_path, "CQL", "    maple: {horizon: 5}\n")])
    assert rc == 2 and "needs run: MAPLE or MOPO" in err and "x.config.maple" in err


def test_a_real_run_without_data_fails_before_ray_naming_make_datasets(
    capsys, tmp_path, monkeypatch
):
    import ray

    monkeypatch.chdir(tmp_path)  # no data/offline/ here, whether or not the checkout has it
    was_up = ray.is_initialized()
    rc, err = _err(capsys, ["train", "file", str(EXAMPLES / "maple-hopper.yaml")])
    assert rc == 2 and "make datasets" in err and "maple-hopper.config.input" in err
    assert ray.is_initialized() == was_up  # Ray never started


@pytest.mark.parametrize(
    ("name", "context", "horizon", "cls"),
    [
        ("maple-hopper", True, 10, "MapleConfig"),
        ("maple-asor-hopper", True, 10, "MapleConfig"),
        ("mopo-hopper", False, 5, "MopoConfig"),
    ],
)
def test_tuned_examples_build_their_configs(name, context, horizon, cls):
    exp = experiment.load_file(str(EXAMPLES / f"{name}.yaml"))[0]
    cfg = experiment.build_algo_config(exp)
    assert type(cfg).__name__ == cls
    assert cfg.settings.context is context and cfg.settings.horizon == horizon
    assert len(cfg.input_) == 3 and all("/medium" in p for p in cfg.input_)
    # the Tune param space carries the merged settings back into a trial's config
    space = experiment.param_space(exp, cfg)
    again = type(cfg)().update_from_dict(
        {k: v for k, v in space.items() if k not in ("asor", "rllib_asor_run")}
    )
    assert again.settings == cfg.settings
    assert (exp.asor is not None) == (name == "maple-asor-hopper")


@pytest.mark.slow
def test_maple_asor_example_runs_with_test_stand_in_data(ray_session, tmp_path, capsys):
    rc = main(
        [
            "train",
            "file",
            str(EXAMPLES / "maple-asor-hopper.yaml"),
            "--test",
            "--storage-path",
            str(tmp_path),
        ]
    )
    assert rc == 0, capsys.readouterr().err
    assert list(tmp_path.glob("maple-asor-hopper-test/*/checkpoint_*"))
