"""ASOR reaches every algorithm through one door: `asor_update` is called by the `AsorTrainer`
only, and the trainer by the ASOR learner-connector piece only, the bonus is normalised in one function, no Learner reads the
piece's state, and each ASOR Learner's differences live in its algorithm's adapter."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import rllib_asor

PACKAGE = Path(rllib_asor.__file__).parent


def _calls(name: str) -> list[str]:
    """`file:function` of every call of `name` (as `name(...)` or `x.name(...)`) in the package."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(), str(path))
        for fn in ast.walk(tree):
            if not isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef):
                continue
            for node in ast.walk(fn):
                if isinstance(node, ast.Call):
                    f = node.func
                    called = f.id if isinstance(f, ast.Name) else getattr(f, "attr", None)
                    if called == name:
                        found.append(f"{path.relative_to(PACKAGE)}:{fn.name}")
    return sorted(set(found))


def test_asor_update_runs_from_the_trainer_and_the_trainer_from_the_connector_piece_only():
    assert _calls("asor_update") == ["asor/trainer.py:rank"]
    assert _calls("rank") == ["asor/trainer.py:step", "rllib/connector.py:_augment"]
    assert _calls("learn") == ["asor/trainer.py:step", "rllib/connector.py:_augment"]


def test_the_bonus_is_normalised_in_one_function():
    assert _calls("standardize") == ["asor/update.py:_bonus_normaliser"]
    assert _calls("_bonus_normaliser") == [
        "asor/update.py:asor_update",
        "asor/update.py:bonus_for_rows",
    ]


def test_no_learner_reads_the_pieces_state():
    """The Learner builds, inserts and calls its piece; what it needs travels in the batch."""
    reads = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if (
                isinstance(node, ast.Attribute)
                and isinstance(node.value, ast.Attribute)
                and node.value.attr == "_asor_piece"
            ):
                reads.append(f"{path.relative_to(PACKAGE)}: _asor_piece.{node.attr}")
    assert reads == []


@pytest.mark.parametrize(
    ("learner", "algorithm"),
    [
        ("rllib_asor.rllib.learners:AsorPPOTorchLearner", "ppo"),
        ("rllib_asor.rllib.learners:AsorSACTorchLearner", "sac"),
        ("rllib_asor.rllib.learners:AsorCQLTorchLearner", "cql"),
        ("rllib_asor.rllib.learners:AsorESCPTorchLearner", "sac"),
        ("rllib_asor.rllib.learners:AsorMapleTorchLearner", "maple"),
    ],
)
def test_each_asor_learner_takes_its_algorithms_adapter(learner, algorithm):
    import importlib

    from rllib_asor.algorithms.common.asor_adapter import AsorAdapter

    module, name = learner.split(":")
    cls = getattr(importlib.import_module(module), name)
    adapter = cls.asor_adapter
    assert isinstance(adapter, AsorAdapter)
    assert type(adapter).__module__ == f"rllib_asor.algorithms.{algorithm}.asor_adapter"
    # the places differ as the algorithms do: before GAE (PPO), in the pipeline or by the
    # Learner (SAC, ESCP: fast path), by the Learner only (offline CQL, MAPLE)
    assert adapter.in_pipeline == (algorithm not in ("cql", "maple"))
    assert (adapter.insert_before is not None) == (algorithm == "ppo")
    assert (adapter.bonus_column is not None) == (algorithm == "maple")
