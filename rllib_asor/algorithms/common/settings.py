"""Checks shared by the algorithms' own settings blocks (`escp:`, `maple:`): the predicates
behind "key=value is invalid" and the unknown-key error with its "did you mean"."""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable, Iterable, Sequence
from typing import Any


def is_int_at_least(lo: int) -> Callable[[Any], bool]:
    """A predicate: an int (not a bool) ≥ `lo`."""
    return lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= lo


def is_number(lo: float, hi: float | None = None, open_low: bool = False) -> Callable[[Any], bool]:
    """A predicate: a finite int/float (not a bool) ≥ `lo` (> with `open_low`) and ≤ `hi`."""

    def ok(v: Any) -> bool:
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            return False
        return (v > lo if open_low else v >= lo) and (hi is None or v <= hi)

    return ok


def refuse_unknown(block: str, label: str, given: Iterable[str], names: Sequence[str]) -> None:
    """ValueError naming the first key of `given` not in `names` (with the closest name)."""
    for key in given:
        if key not in names:
            close = difflib.get_close_matches(key, names, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ValueError(
                f"{block}.{key} is not {label} setting{hint}: allowed {', '.join(names)}"
            )
