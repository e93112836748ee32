"""`rllib schema`: the JSON Schema of our YAML experiment files. The package file is the
generated one, every tuned example passes it, the bad inputs the CLI tests refuse fail it, and
the `asor:` block's schema takes and refuses what `AsorConfig` takes and refuses."""

from __future__ import annotations

import json
import math
from pathlib import Path

import jsonschema
import pytest
import yaml

from rllib_asor.cli import schema
from rllib_asor.cli.main import main
from tests.asor.test_config_behaviour import BOUNDS

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = sorted((ROOT / "tuned_examples").rglob("*.yaml"))


@pytest.fixture(scope="module")
def validator() -> jsonschema.Draft202012Validator:
    generated = schema.experiment_schema()
    jsonschema.Draft202012Validator.check_schema(generated)
    return jsonschema.Draft202012Validator(generated)


def _errors(validator: jsonschema.Draft202012Validator, text: str) -> list[str]:
    return [e.message for e in validator.iter_errors(yaml.safe_load(text))]


def test_the_package_file_is_the_generated_schema():
    assert schema.SCHEMA_FILE.read_text(encoding="utf-8") == schema.schema_text(), (
        "rllib_asor/cli/experiment.schema.json is stale: run `rllib schema --write`"
    )


def test_rllib_schema_prints_the_generated_schema(capsys):
    assert main(["schema"]) == 0
    printed = capsys.readouterr().out
    assert printed == schema.schema_text()
    assert json.loads(printed)["$schema"] == schema.DIALECT


def test_the_run_names_are_rllibs_and_ours_from_the_registries():
    from ray.rllib.algorithms.registry import ALGORITHMS as RLLIB

    from rllib_asor.registry.algorithms import ALGORITHMS as OURS

    names = schema.run_names()
    assert set(names) == set(RLLIB) | set(OURS) and {"PPO", "ESCP", "MAPLE", "MOPO"} <= set(names)


@pytest.mark.parametrize("path", EXAMPLES, ids=[str(p.relative_to(ROOT)) for p in EXAMPLES])
def test_every_tuned_example_passes_the_schema(validator, path):
    assert len(EXAMPLES) >= 30
    assert _errors(validator, path.read_text()) == []


HEAD = "x:\n  env: CartPole-v1\n  run: PPO\n"
ESCP = "x:\n  env: rllib_asor/HalfCheetahShift-v0\n  run: ESCP\n"
MAPLE = "x:\n  env: rllib_asor/HopperShift-v0\n  run: MAPLE\n"
BAD = [  # the bad inputs of tests/cli/test_errors.py, tests/algorithms/*/test_*_cli.py
    HEAD + "  config:\n    asor: {rho_value: 1.5}\n",
    HEAD + "  config:\n    asor: {rho_count: 0}\n",
    HEAD + "  config:\n    asor: {lambda_: -0.1}\n",
    HEAD + "  config:\n    asor: {lambda: -1}\n",
    HEAD + "  config:\n    asor: {rho_value: {grid_search: [0.5, 2.0]}}\n",
    HEAD + "  config:\n    asor: {lambda_: {grid_search: [0.1, -1]}}\n",
    HEAD + "  config:\n    asor: {proxy: counts}\n",
    HEAD + "  config:\n    asor: {rhovalue: 0.5}\n",
    HEAD + "  config: {asor: {lamda_: 0.1}}\n",
    HEAD + "  config: {asor: {lambda: 0.1, lambda_: 0.2}}\n",
    HEAD + "  stopp: {}\n",
    HEAD + "  checkpoint_config: {num_to_keep: 0}\n",
    HEAD + "  checkpoint_config: {checkpoint_freq: 5}\n",
    HEAD + "  num_samples: 0\n",
    HEAD + "  stop: {training_iteration: many}\n",
    "x:\n  env: CartPole-v1\n  run: PPOO\n",
    "x:\n  env: CartPole-v1\n",
    "x:\n  run: PPO\n",
    ESCP + "  config:\n    escp: {history_len: 0}\n",
    ESCP + "  config:\n    escp: {windw: 5}\n",
    ESCP + "  config:\n    escp: {kernel: {grid_search: [rbf, inner]}}\n",
    HEAD.replace("PPO", "SAC") + "  config:\n    escp: {history_len: 8}\n",
    MAPLE + "  config:\n    maple: {horizon: 0}\n",
    MAPLE + "  config:\n    maple: {horizn: 5}\n",
    HEAD + "  config:\n    maple: {horizon: 5}\n",
    MAPLE + "  config:\n    dara: {eta: -1}\n",
    MAPLE + "  config:\n    dara: {target_dynamic: x}\n",
    HEAD + "  config:\n    dara: {eta: 0.1}\n",
    ESCP.replace("ESCP", "OSI") + "  config:\n    osi: {history_len: 0}\n",
    ESCP + "  config:\n    osi: {history_len: 8}\n",
    ESCP + "  config:\n    cadm: {back_coeff: -1}\n",
]


@pytest.mark.parametrize("text", BAD)
def test_the_bad_inputs_of_the_cli_tests_fail_the_schema(validator, text):
    assert _errors(validator, text), text


def test_a_good_file_with_grids_blocks_and_legacy_keys_passes(validator):
    text = (
        HEAD
        + "  checkpoint_freq: 5\n  num_samples: 2\n  stop: {episode_reward_mean: 100}\n"
        + "  config:\n    lr: {grid_search: [0.1, 0.01]}\n    num_workers: 2\n"
        + "    asor: {lambda: 0.1, rho_value: {grid_search: [0.3, 0.5]}, obs_keys: [a]}\n"
    )
    assert _errors(validator, text) == []
    assert _errors(validator, "x:\n  run: PPO\n  config: {env: CartPole-v1}\n") == []


def _finite_json(value) -> bool:
    """Values JSON Schema can tell apart as the class does: no nan/inf (JSON has none), no
    tuples (JSON has lists only), no integral floats (JSON Schema's integer takes 1.0)."""
    if isinstance(value, float):
        return math.isfinite(value) and not value.is_integer()
    if isinstance(value, tuple):
        return False  # JSON has lists only
    return not isinstance(value, list) or all(_finite_json(v) for v in value)


@pytest.mark.parametrize("key, good, bad, allowed", BOUNDS, ids=[b[0] for b in BOUNDS])
def test_the_asor_block_schema_takes_and_refuses_what_asor_config_does(key, good, bad, allowed):
    block = jsonschema.Draft202012Validator(schema.block_schema("asor"))
    for value in filter(_finite_json, good):
        assert block.is_valid({key: value}), value
    for value in filter(_finite_json, bad):
        assert not block.is_valid({key: value}), value


@pytest.mark.parametrize("name", ["asor", "escp", "maple", "dara", "osi", "cadm"])
def test_each_block_schema_is_strict_and_names_every_setting(name):
    from rllib_asor.cli.spec import SETTINGS_BLOCKS

    block = SETTINGS_BLOCKS[name]
    cls = block.settings_class()
    generated = schema.block_schema(name)
    extra = {"ensemble"} if name == "maple" else set()  # the named-ensemble key
    assert set(generated["properties"]) == set(cls.model_fields) | set(block.aliases) | extra
    assert generated["additionalProperties"] is False
    validator = jsonschema.Draft202012Validator(generated)
    assert validator.is_valid(cls().to_dict())  # the defaults pass
    assert not validator.is_valid({"no_such_setting": 1})


@pytest.mark.parametrize("text", BAD)
def test_what_the_schema_refuses_the_cli_refuses_in_one_line_naming_the_key(text, tmp_path):
    from rllib_asor.cli.errors import UsageError
    from rllib_asor.cli.spec import load_file
    from rllib_asor.cli.validate import check_file

    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(UsageError) as refused:
        for exp in load_file(str(path)):
            check_file(exp)
    line = str(refused.value)
    assert "\n" not in line and f"{path}: x." in line, line


@pytest.mark.parametrize(
    ("run", "env", "block", "attr"),
    [
        ("ESCP", "rllib_asor/HalfCheetahShift-v0", "escp: {history_len: 8}", "escp_settings"),
        ("MAPLE", "rllib_asor/HopperShift-v0", "maple: {horizon: 3}", "maple_settings"),
        ("MAPLE", "rllib_asor/HopperShift-v0", "dara: {eta: 0.2}", "dara_settings"),
        ("OSI", "rllib_asor/HalfCheetahShift-v0", "osi: {history_len: 8}", "osi_settings"),
        ("CaDM", "rllib_asor/HalfCheetahShift-v0", "cadm: {history_len: 8}", "cadm_settings"),
    ],
)
def test_each_block_reaches_its_config_attribute(run, env, block, attr, tmp_path):
    from rllib_asor.cli.build import build_algo_config
    from rllib_asor.cli.spec import load_file
    from rllib_asor.cli.validate import check_file

    text = f"x:\n  env: {env}\n  run: {run}\n  config:\n    {block}\n"
    if run == "MAPLE":
        text += "    input: [data/offline/hopper/original/medium]\n"
    path = tmp_path / "ok.yaml"
    path.write_text(text)
    assert _errors(jsonschema.Draft202012Validator(schema.experiment_schema()), text) == []
    exp = load_file(str(path))[0]
    check_file(exp)
    (settings,) = yaml.safe_load(block).values()
    ((key, value),) = settings.items()
    assert getattr(build_algo_config(exp), attr)[key] == value
