"""Known-harmless Ray / RLlib / Tune / gymnasium messages, kept off the `rllib` output.

Every line matching `HARMLESS` is dropped: from the driver's loggers and from the worker
lines Ray forwards to the driver. Set `RLLIB_ASOR_VERBOSE=1` (or pass `--verbose`) to see
everything; nothing else is filtered, so real warnings and errors still show.
"""

from __future__ import annotations

import logging
import os
import re
import warnings
from typing import Any

from rllib_asor import ray_compat as compat

VERBOSE_ENV = "RLLIB_ASOR_VERBOSE"
HARMLESS = re.compile(
    "|".join(
        re.escape(s)
        for s in (
            "Token authentication is enabled",  # every local ray.init
            "Started a local Ray instance",
            "on the new API stack! This is the new default",  # RLlib, per algorithm
            "has constructor arguments in the object store and max_restarts > 0",  # core_worker
            "RLModule(config=[RLModuleConfig object])",  # RLlib-internal deprecation
            "Install gputil for GPU system monitoring",
            "Checkpoint successfully created at",
            "Wrote the latest version of all result files",
            "Total run time:",
            "To visualize your results with TensorBoard",
            "View detailed results here",
            "If your trainable is slow to initialize",  # Tune, on a loaded machine
            # Ray Data (offline runs): progress chatter and its own deprecations
            "Starting execution of Dataset",
            "Execution plan of Dataset",
            "execution finished in",
            "Data sink Parquet finished",
            "A new progress UI is available",
            "tqdm is not installed",
            "The argument ``concurrency`` is deprecated",
            "OfflinePreLearner(module_spec=..)",
            "won't fully utilize the available concurrency",
            "  warnings.warn(",  # the second line of a Python warning already dropped
            "PYTHON worker processes have been started",  # raylet, fractional-CPU actors
            # gymnasium, once per env runner: RLlib re-registers its own wrapper env id
            "Overriding environment rllib-single-agent-env-v0",
            "Overriding environment rllib-multi-agent-env-v0",
            'logger.warn(f"Overriding environment {new_spec.id} already in registry.")',
        )
    )
)
"""Substrings of the messages dropped (each seen on every run, none actionable)."""
RAY_LOGGERS = ("ray", "ray.tune", "ray.rllib", "ray.train", "gymnasium")
RLLIB_ENV_OVERRIDE = r".*Overriding environment rllib-(single|multi)-agent-env-v0 "
"""gymnasium's warning (a Python warning in the driver) when RLlib re-registers its env id."""


def verbose() -> bool:
    """Whether the user asked for every message."""
    return os.environ.get(VERBOSE_ENV, "").lower() in ("1", "true", "yes")


class _DropHarmless(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return not HARMLESS.search(record.getMessage())


def quiet_driver() -> None:
    """Filter the driver's loggers and Python warnings (imports Ray; again after `ray.init`)."""
    if verbose():
        return
    import ray.rllib  # noqa: F401 - sets up the "ray" and "ray.rllib" handlers filtered here

    drop = _DropHarmless()
    for name in RAY_LOGGERS:
        logger = logging.getLogger(name)
        if not any(isinstance(f, _DropHarmless) for f in logger.filters):
            logger.addFilter(drop)
        for handler in logger.handlers:
            if not any(isinstance(f, _DropHarmless) for f in handler.filters):
                handler.addFilter(drop)
    warnings.filterwarnings("ignore", category=DeprecationWarning, module="ray")
    warnings.filterwarnings("ignore", message=RLLIB_ENV_OVERRIDE)


def import_quietly(module: str) -> None:
    """Import `module` with its import-time warnings hidden (unless verbose); later imports
    are cached. For RLlib's DreamerV3 debugging envs, imported while unpickling checkpoints,
    which warn about their own float64 Box bounds and reset() dtype."""
    import importlib

    if verbose():
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        importlib.import_module(module)


def quiet_worker_lines() -> None:
    """Drop the harmless lines among the worker output Ray forwards (call after `ray.init`)."""
    if verbose():
        return
    compat.edit_worker_output_handlers(  # a Ray without this hook: show everything
        lambda handlers: [
            (name, handler if name != "ray_print_logs" else _filtered(handler))
            for name, handler in handlers
        ]
    )


def _filtered(handler: Any) -> Any:
    if getattr(handler, "_drops_harmless", False):
        return handler

    def emit(data: dict[str, Any]) -> None:
        lines = [line for line in data.get("lines", ()) if not HARMLESS.search(line)]
        if lines:
            handler({**data, "lines": lines})

    emit._drops_harmless = True  # type: ignore[attr-defined]
    return emit
