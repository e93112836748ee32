"""A checkpoint written before ASOR trained its own networks names module classes this version
no longer has: `rllib evaluate` refuses it in one line that says so and what is allowed."""

from __future__ import annotations

import pickle
import sys

import pytest

import rllib_asor.rllib.modules as modules
from rllib_asor.cli.evaluate import CHECKPOINT_MARKER, CTOR_FILE


@pytest.mark.parametrize("retired", modules.RETIRED_CLASSES)
def test_evaluate_refuses_a_checkpoint_of_the_older_modules_in_one_line(
    retired, tmp_path, capsys
):
    old = type(retired, (), {"__module__": modules.__name__, "__qualname__": retired})
    setattr(modules, retired, old)  # only while the old checkpoint's config is written
    try:
        spec = {"module_class": old}
        ctor = {"ctor_args_and_kwargs": (({"env": "CartPole-v1", "rl_module": spec},), {})}
        ckpt = tmp_path / "checkpoint_000000"
        ckpt.mkdir()
        (ckpt / CTOR_FILE).write_bytes(pickle.dumps(ctor))
        (ckpt / CHECKPOINT_MARKER).write_text("{}")
    finally:
        delattr(modules, retired)
    assert retired not in vars(sys.modules[modules.__name__])

    from rllib_asor.cli.main import main

    rc = main(["evaluate", str(ckpt), "--episodes", "1"])
    err = capsys.readouterr().err
    assert rc == 2, err[-2000:]
    assert len(err.strip().splitlines()) == 1, err
    assert "older rllib-asor" in err and "allowed:" in err and str(ckpt) in err
