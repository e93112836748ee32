"""The one exception the CLI turns into one line per problem and exit status 2, the collector
that reports every problem of a file at once, and helpers to keep library noise out of the
checks that raise it."""

from __future__ import annotations

import contextlib
import logging
import warnings
from collections.abc import Callable, Iterator
from typing import Any


class UsageError(Exception):
    """Bad input (file, key or value): printed as one line on stderr, exit status 2. One error
    may stand for several problems (`Problems`): one line each."""

    def __init__(self, message: str, *, source: str | None = None, key: str | None = None):
        self.source = source
        self.key = key
        self.problems: list[UsageError] = [self]
        super().__init__(message)

    def __str__(self) -> str:
        if self.problems != [self]:
            return "\n".join(str(p) for p in self.problems)
        parts = [p for p in (self.source, self.key) if p]
        prefix = ": ".join(parts)
        msg = super().__str__()
        return f"{prefix}: {msg}" if prefix else msg


class Problems:
    """The problems of independent checks, so that a file's every mistake is reported at once:
    run each check in `with problems.check():`, then `problems.raise_any()` raises one
    UsageError standing for all of them (each once, in order)."""

    def __init__(self) -> None:
        self.found: list[UsageError] = []

    @contextlib.contextmanager
    def check(self) -> Iterator[None]:
        """Run one check; its UsageError (every problem in it) is kept instead of raised."""
        try:
            yield
        except UsageError as e:
            for problem in e.problems:
                self.add(problem)

    def passed(self, check: Callable[..., Any], *args: Any) -> bool:
        """Run `check(*args)`, its UsageError kept; whether it passed (a later check that
        needs it can then be skipped)."""
        with self.check():
            check(*args)
            return True
        return False

    def add(self, problem: UsageError) -> None:
        """Keep one problem (a problem already kept is kept once)."""
        if str(problem) not in {str(p) for p in self.found}:
            self.found.append(problem)

    def __bool__(self) -> bool:
        return bool(self.found)

    def raise_any(self) -> None:
        if len(self.found) == 1:
            raise self.found[0]
        if self.found:
            error = UsageError(f"{len(self.found)} problems")
            error.problems = list(self.found)
            raise error


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
