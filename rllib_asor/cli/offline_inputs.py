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


def check_demonstrations(exp: Experiment) -> None:
    """A `demonstrations:` path of an imitation block that does not exist fails here, before
    Ray starts (relative paths: from the working directory, where Tune starts)."""
    for key in DEMONSTRATION_KEYS:
        given = _demonstrations_path(exp, key)
        if given and not os.path.exists(given):
            from rllib_asor.algorithms.common.demonstrations import ALLOWED

            hint = (
                "; make the offline datasets first: `make datasets`" if "offline" in given else ""
            )
            raise UsageError(
                f"demonstrations {given} do not exist{hint}; {ALLOWED}",
                source=exp.source,
                key=f"{exp.name}.config.{key.removesuffix('_settings')}.demonstrations",
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
    demos = _missing_demonstrations(exp, missing)
    missing += [p for parts, _ in demos.values() for p in parts if p not in missing]
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
    for key, (parts, whole_task) in demos.items():  # the stand-in task dir or part
        stand_in = Path(swap[parts[0]])
        path = stand_in.parent.parent if whole_task else stand_in
        exp.config[key] = {**exp.config[key], "demonstrations": str(path)}
    exp.warnings.append(
        f"--test: trained on tiny stand-in datasets in {tmp} (deleted at exit); "
        "for real runs make the data first: `make datasets`"
    )


DEMONSTRATION_KEYS = ("bco_settings", "soil_settings", "gaifo_settings")
"""Config keys of the blocks whose `demonstrations:` may name a `rllib data collect` dataset."""


def _demonstrations_path(exp: Experiment, key: str) -> str:
    block = exp.config.get(key)
    path = block.get("demonstrations") if isinstance(block, dict) else None
    return path if isinstance(path, str) else ""


def _missing_demonstrations(
    exp: Experiment, inputs: list[str]
) -> dict[str, tuple[list[str], bool]]:
    """{block key: (the dataset parts its missing `demonstrations:` needs, whether it names the
    whole task dir)} for blocks whose demonstrations are a part (`.../hopper/original/expert`)
    or the task dir of the missing inputs (`.../hopper`: the expert level of the inputs'
    dynamics); made beside the inputs' stand-ins under --test."""
    from rllib_asor.data.format import DYNAMICS, QUALITIES

    out: dict[str, tuple[list[str], bool]] = {}
    dynamics = sorted({Path(p).parent.name for p in inputs})
    roots = {Path(p).parent.parent: dynamics for p in inputs}
    for key in DEMONSTRATION_KEYS:
        given = _demonstrations_path(exp, key)
        if not given:
            continue
        path = Path(given) if os.path.isabs(given) else Path.cwd() / given
        if path.exists():
            continue
        if path.parent.name in DYNAMICS and path.name in QUALITIES:
            out[key] = ([str(path)], False)
        elif path in roots:
            out[key] = ([str(path / d / "expert") for d in roots[path]], True)
    return out
