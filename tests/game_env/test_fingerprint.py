"""The race behaves exactly as recorded: every scenario of ``fingerprint.py`` hashes the same.

``fingerprint.json`` was recorded from the code before the game_env refactor; a
refactor must leave every observation, reward, termination and info bit-identical. Re-record
(``python -m tests.game_env.fingerprint --write``) only for an intended behaviour change, and
say so in the commit. The hashes are of float bits on this platform's MuJoCo build.
"""

from __future__ import annotations

import json
import warnings

import pytest

from tests.game_env.fingerprint import FIXTURE, SCENARIOS, _errors

RECORDED = json.loads(FIXTURE.read_text())


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_scenario_matches_the_recorded_fingerprint(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        got = SCENARIOS[name]()
    want = RECORDED[name]
    # Summaries first: a mismatch there says which reward term moved.
    assert (got["steps"], got["terms"]) == (want["steps"], want["terms"])
    assert got["sha256"] == want["sha256"]


def test_argument_errors_match_the_recorded_messages():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        got = _errors()
    assert got == RECORDED["argument errors"]["messages"]
