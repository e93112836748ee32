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
            "obs returned by the `reset()` method is not within the observation space",
            "is deprecated and will be removed",  # Ray's own API moves (Tune, RLlib)
            "To visualize your results with TensorBoard",
            "View detailed results here",
            "If your trainable is slow to initialize",  # Tune, on a loaded machine
        )
    )
)
"""Substrings of the messages dropped (each seen on every run, none actionable)."""
RAY_LOGGERS = ("ray", "ray.tune", "ray.rllib", "ray.train", "gymnasium")


def verbose() -> bool:
    """Whether the user asked for every message."""
    return os.environ.get(VERBOSE_ENV, "").lower() in ("1", "true", "yes")


class _DropHarmless(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return not HARMLESS.search(record.getMessage())


def quiet_driver() -> None:
    """Filter the driver's loggers and Python warnings (call before `ray.init`)."""
    if verbose():
        return
    drop = _DropHarmless()
    for name in RAY_LOGGERS:
        logger = logging.getLogger(name)
        if not any(isinstance(f, _DropHarmless) for f in logger.filters):
            logger.addFilter(drop)
        for handler in logger.handlers:
            if not any(isinstance(f, _DropHarmless) for f in handler.filters):
                handler.addFilter(drop)
    warnings.filterwarnings("ignore", message=".*not within the observation space")
    warnings.filterwarnings("ignore", category=DeprecationWarning, module="ray")


def quiet_worker_lines() -> None:
    """Drop the harmless lines among the worker output Ray forwards (call after `ray.init`)."""
    if verbose():
        return
    try:
        from ray._private.ray_logging import global_worker_stdstream_dispatcher as dispatcher
    except ImportError:  # a Ray without this hook: show everything
        return
    with dispatcher._lock:
        dispatcher.handlers = [
            (name, handler if name != "ray_print_logs" else _filtered(handler))
            for name, handler in dispatcher.handlers
        ]


def _filtered(handler: Any) -> Any:
    if getattr(handler, "_drops_harmless", False):
        return handler

    def emit(data: dict[str, Any]) -> None:
        lines = [line for line in data.get("lines", ()) if not HARMLESS.search(line)]
        if lines:
            handler({**data, "lines": lines})

    emit._drops_harmless = True  # type: ignore[attr-defined]
    return emit
