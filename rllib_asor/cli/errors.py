"""The one exception the CLI turns into a one-line message and exit status 2, and helpers
to keep library noise out of the checks that raise it."""

from __future__ import annotations

import contextlib
import logging
import warnings
from collections.abc import Iterator


class UsageError(Exception):
    """Bad input (file, key or value): printed as one line on stderr, exit status 2."""

    def __init__(self, message: str, *, source: str | None = None, key: str | None = None):
        self.source = source
        self.key = key
        super().__init__(message)

    def __str__(self) -> str:
        parts = [p for p in (self.source, self.key) if p]
        prefix = ": ".join(parts)
        msg = super().__str__()
        return f"{prefix}: {msg}" if prefix else msg


@contextlib.contextmanager
def quiet() -> Iterator[None]:
    """Keep RLlib's import-time/log warnings off stderr while we validate."""
    prev = logging.root.manager.disable
    logging.disable(logging.WARNING)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            yield
    finally:
        logging.disable(prev)


def one_line(e: BaseException) -> str:
    """An exception as one line (its text with whitespace collapsed, else its type)."""
    return " ".join(str(e).split()) or type(e).__name__
