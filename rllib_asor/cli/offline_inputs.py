"""Offline `input` paths: refuse missing ones before Ray starts; `--test` builds stand-ins."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from rllib_asor.cli.errors import UsageError, quiet
from rllib_asor.cli.spec import Experiment


def missing_inputs(value: Any) -> list[str]:
    """The local paths of an offline `input` value that do not exist."""
    paths = value if isinstance(value, list) else [value]
    return [p for p in paths if isinstance(p, str) and os.path.isabs(p) and not os.path.exists(p)]


def check_offline_input(exp: Experiment) -> None:
    """A local offline `input` that does not exist fails here, before Ray starts."""
    missing = missing_inputs(exp.config.get("input"))
    if missing:
        hint = (
            "; make the offline datasets first: `make datasets` (about 10 minutes on 2 cores, "
            "docs/offline.md)"
            if any("data/offline" in p for p in missing)
            else "; give `input:` a dataset folder made by `rllib data collect` (docs/offline.md) "
            "or RLlib's new-stack offline data (parquet episodes)"
        )
        raise UsageError(
            f"offline input {missing[0]} does not exist{hint}",
            source=exp.source,
            key=f"{exp.name}.config.input",
        )


def tiny_test_data(exp: Experiment) -> None:
    """--test on a fresh clone: stand-ins for the missing datasets, in a temporary folder."""
    from rllib_asor.data.format import DYNAMICS, QUALITIES

    missing = [  # only our dataset layout `.../<task>/<dynamics>/<quality>` has stand-ins
        p
        for p in missing_inputs(exp.config.get("input"))
        if Path(p).parent.name in DYNAMICS and Path(p).name in QUALITIES
    ]
    if not missing:
        return
    import atexit
    import shutil
    import tempfile

    from rllib_asor.data.collect import TINY_STEPS, tiny_datasets

    tmp = tempfile.mkdtemp(prefix="rllib-asor-test-data-")
    atexit.register(shutil.rmtree, tmp, ignore_errors=True)
    print(
        f"rllib: --test: {len(missing)} offline dataset(s) missing (e.g. {missing[0]}); building "
        f"tiny stand-ins ({TINY_STEPS} steps each, untrained policy; not for results) ...",
        flush=True,
    )
    with quiet():
        swap = tiny_datasets(exp.env, missing, tmp)
    value = exp.config["input"]
    exp.config["input"] = (
        [swap.get(p, p) for p in value] if isinstance(value, list) else swap.get(value, value)
    )
    exp.warnings.append(
        f"--test: trained on tiny stand-in datasets in {tmp} (deleted at exit); "
        "for real runs make the data first: `make datasets`"
    )
