"""Every YAML under tuned_examples/ parses and validates as a new user's `rllib train` would.

Behaviour, not values: each file loads without legacy-key warnings and passes
`experiment.validate` (env built, `AlgorithmConfig.validate()`, the `asor:` block checked for
every grid point); an offline example whose dataset is not there fails with the message that
names `make datasets`. `--test` runs of representative examples are in tests/cli,
tests/race and tests/examples.
"""

from __future__ import annotations

import runpy
from pathlib import Path

import pytest

from rllib_asor.cli import experiment
from rllib_asor.cli.errors import UsageError

pytestmark = pytest.mark.heavy  # starts Ray or a subprocess: scheduled first (conftest)

REPO = Path(__file__).resolve().parents[2]
EXAMPLES = sorted((REPO / "tuned_examples").rglob("*.yaml"))
DEMOS = REPO / "tuned_examples/paper/demonstrations"


@pytest.fixture(scope="module", autouse=True)
def _paper_demonstrations():
    """The paper's sweep files read demonstrations that `make install` writes (make.py beside
    them); a bare `pytest` writes them here the same way."""
    names = ("lava-expert.npz", "walker2d-gravity-random.npz", "halfcheetah-damping-random.npz")
    if not all((DEMOS / n).exists() for n in names):
        runpy.run_path(str(DEMOS / "make.py"), run_name="__main__")


def test_there_are_examples_of_every_kind():
    assert {p.parent.name for p in EXAMPLES} >= {
        "lava",
        "race",
        "mujoco",
        "highway",
        "offline",
        "sweeps",
    }


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_example_parses_and_validates(path, monkeypatch):
    monkeypatch.chdir(REPO)  # offline `input` paths are relative to the repository root
    for exp in experiment.load_file(str(path)):
        assert exp.warnings == []  # our own files use no legacy keys
        assert exp.num_trials >= 1
        if experiment.missing_inputs(exp.config.get("input")):
            with pytest.raises(UsageError, match="make datasets"):
                experiment.validate(exp)
            continue
        config = experiment.validate(exp)
        assert config.env == exp.env


def test_plain_sac_and_cql_files_get_the_fast_off_policy_path(tmp_path):
    """`rllib train file sac-hopper.yaml` gets the fast path (docs/speed.md) without ASOR; a file can
    opt out with `learner_config_dict: {fast_off_policy: false}`."""
    from rllib_asor.algorithms.sac.learner import FastSACTorchLearner

    [exp] = experiment.load_file(str(REPO / "tuned_examples/mujoco/sac-hopper.yaml"))
    config = experiment.validate(exp)
    assert config.learner_class is FastSACTorchLearner
    assert config.replay_buffer_config["storage"] == "flat"
    text = (REPO / "tuned_examples/mujoco/sac-hopper.yaml").read_text()
    path = tmp_path / "optout.yaml"
    path.write_text(
        text.replace(
            "  config:\n", "  config:\n    learner_config_dict: {fast_off_policy: false}\n", 1
        )
    )
    [exp] = experiment.load_file(str(path))
    assert experiment.validate(exp).learner_class is not FastSACTorchLearner
