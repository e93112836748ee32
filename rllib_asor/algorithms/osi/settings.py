"""`OsiSettings`: OSI's own settings (the YAML `osi:` block, `OsiConfig.osi(...)`), validated.

Defaults are the authors' (`VincentYu68/policy_transfer policy_transfer/uposi/train_osi.py`:
`--OSI_hist 10`, OSI layers 256-128-64) where they have one; the rest are ESCP's (the SAC the
universal policy trains with here). A bad value raises ValueError naming the key, the value and
what is allowed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from rllib_asor.algorithms.common.settings import is_int_at_least, is_number, refuse_unknown


@dataclass(frozen=True)
class OsiSettings:
    """OSI's settings; each field names the authors' parameter where there is one."""

    history_len: int = 10
    """H, steps of (s_t, a_{t−1}) OSI reads (`OSI_hist`)."""
    osi_hidden: tuple[int, ...] = (256, 128, 64)
    """OSI's hidden ReLU layers (`layers=[256, 128, 64]`)."""
    osi_lr: float = 1e-3
    """Adam lr of the OSI network."""
    osi_weight: float = 1.0
    """Factor on OSI's squared error (0: OSI does not train)."""
    param_dim: int | None = None
    """Length of `info["dynamics_params"]`; None: read from the env when the config is built."""
    target_entropy_ratio: float = 1.0
    """SAC's target entropy −ratio·|A| for `target_entropy="auto"` (SAC's own: 1)."""

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | OsiSettings | None) -> OsiSettings:
        """Settings from a dict (the `osi:` block); unknown keys and bad values raise
        ValueError."""
        if d is None:
            return cls()
        if isinstance(d, OsiSettings):
            return d
        if not isinstance(d, Mapping):
            raise ValueError(f"osi={d!r} is not allowed; expected a mapping of OSI settings")
        refuse_unknown("osi", "an OSI", d, [f.name for f in dataclasses.fields(cls)])
        values = dict(d)
        for key, ok, allowed in (
            ("history_len", is_int_at_least(1), "an int ≥ 1"),
            ("osi_lr", is_number(0.0, None, open_low=True), "a number > 0"),
            ("osi_weight", is_number(0.0), "a number ≥ 0"),
            ("target_entropy_ratio", is_number(0.0), "a number ≥ 0"),
            ("param_dim", lambda v: v is None or is_int_at_least(1)(v), "null or an int ≥ 1"),
            (
                "osi_hidden",
                lambda v: (
                    isinstance(v, list | tuple)
                    and len(v) > 0
                    and all(is_int_at_least(1)(x) for x in v)
                ),
                "a non-empty list of positive ints",
            ),
        ):
            if key in values and not ok(values[key]):
                raise ValueError(f"osi.{key}={values[key]!r} is not allowed; expected {allowed}")
        if "osi_hidden" in values:
            values["osi_hidden"] = tuple(int(x) for x in values["osi_hidden"])
        return cls(**values)

    def to_dict(self) -> dict[str, Any]:
        out = dataclasses.asdict(self)
        out["osi_hidden"] = list(out["osi_hidden"])
        return out
