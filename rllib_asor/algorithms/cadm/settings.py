"""`CadmSettings`: CaDM's own settings (the YAML `cadm:` block, `CadmConfig.cadm(...)`).

Defaults are the authors' (`younggyoseo/CaDM run_scripts/model_free/run_ppo_cadm.py`:
`--history_length 10`, `--context_out_dim 10`, `--back_coeff 0.5`, `context_hidden_sizes
(256, 128, 64)`, `hidden_sizes (200,)*4`, `--lr 0.0005`). A bad value raises ValueError
naming the key, the value and what is allowed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from rllib_asor.algorithms.common.settings import is_int_at_least, is_number, refuse_unknown


def _widths(v: Any) -> bool:
    return isinstance(v, list | tuple) and len(v) > 0 and all(is_int_at_least(1)(x) for x in v)


CHECKS = {
    "history_len": (is_int_at_least(1), "an int ≥ 1"),
    "context_dim": (is_int_at_least(1), "an int ≥ 1"),
    "context_hidden": (_widths, "a non-empty list of positive ints"),
    "model_hidden": (_widths, "a non-empty list of positive ints"),
    "back_coeff": (is_number(0.0), "a number ≥ 0"),
    "model_lr": (is_number(0.0, None, open_low=True), "a number > 0"),
    "model_weight": (is_number(0.0), "a number ≥ 0"),
    "target_entropy_ratio": (is_number(0.0), "a number ≥ 0"),
}


@dataclass(frozen=True)
class CadmSettings:
    """CaDM's settings; each field names the authors' parameter."""

    history_len: int = 10
    """Steps of (s_t, a_{t−1}) the context network reads (`history_length`)."""
    context_dim: int = 10
    """Size of the context c (`context_out_dim`)."""
    context_hidden: tuple[int, ...] = (256, 128, 64)
    """The context network's hidden ReLU layers (`context_hidden_sizes`)."""
    model_hidden: tuple[int, ...] = (200, 200, 200, 200)
    """The forward and backward models' hidden swish layers (`hidden_sizes`)."""
    back_coeff: float = 0.5
    """Weight of the backward model's loss (`back_coeff`)."""
    model_lr: float = 5e-4
    """Adam lr of the context network and the models (`lr`)."""
    model_weight: float = 1.0
    """Factor on CaDM's loss (0: the context is not trained)."""
    target_entropy_ratio: float = 1.0
    """SAC's target entropy −ratio·|A| for `target_entropy="auto"` (SAC's own: 1)."""

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | CadmSettings | None) -> CadmSettings:
        """Settings from a dict (the `cadm:` block); ValueError names a bad key or value."""
        if d is None:
            return cls()
        if isinstance(d, CadmSettings):
            return d
        if not isinstance(d, Mapping):
            raise ValueError(f"cadm={d!r} is not allowed; expected a mapping of CaDM settings")
        refuse_unknown("cadm", "a CaDM", d, [f.name for f in dataclasses.fields(cls)])
        values = dict(d)
        for key, value in values.items():
            ok, allowed = CHECKS[key]
            if not ok(value):
                raise ValueError(f"cadm.{key}={value!r} is not allowed; expected {allowed}")
        for key in ("context_hidden", "model_hidden"):
            if key in values:
                values[key] = tuple(int(x) for x in values[key])
        return cls(**values)

    def to_dict(self) -> dict[str, Any]:
        out = dataclasses.asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in out.items()}
