"""Callbacks on an RLlib config: add ours beside the user's own."""

from __future__ import annotations

from typing import Any

from ray.rllib.callbacks.callbacks import RLlibCallback


def add_callbacks(config: Any, *classes: type) -> Any:
    """Append callback classes to `config`'s own (one class, a list, or none), each once and
    after the others; RLlib's bare `RLlibCallback` default is dropped. Returns `config`."""
    existing = config.callbacks_class
    if existing is None:
        kept: list[type] = []
    elif isinstance(existing, list | tuple):
        kept = list(existing)
    else:
        kept = [existing]
    kept = [c for c in kept if c is not RLlibCallback and c not in classes]
    return config.callbacks(callbacks_class=[*kept, *classes])
