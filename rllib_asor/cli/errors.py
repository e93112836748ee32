"""The one exception the CLI turns into a one-line message and exit status 2."""

from __future__ import annotations


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
