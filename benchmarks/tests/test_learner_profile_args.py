"""benchmarks.learner_profile's arguments (nothing is built): bad input is one line naming the
flag, the value and what is allowed."""

from __future__ import annotations

import pytest

from benchmarks import learner_profile


@pytest.mark.parametrize(
    ("argv", "flag"),
    [
        (["--what", "flames"], "--what"),
        (["--algos", "sac"], "--algos"),
        (["--updates", "0"], "--updates"),
        (["--minibatch", "-1"], "--minibatch"),
    ],
)
def test_bad_arguments_are_one_line_naming_the_flag(argv, flag, capsys) -> None:
    assert learner_profile.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and flag in err[0] and "allowed" in err[0]


def test_every_profile_kind_is_a_choice_of_what() -> None:
    assert set(learner_profile.WHAT) == {"timing", "cprofile", "ops", "syncs", "torch"}
    assert "aten::_local_scalar_dense" in learner_profile.SYNC_OPS
    assert "aten::view" in learner_profile.VIEW_OPS and "aten::mm" not in learner_profile.VIEW_OPS
