"""`DaraSettings`: DARA's settings (the YAML `dara:` block), typed and validated.

Classifier sizes, input noise and the loss are DARC's (`google-research/google-research
darc/classifiers.py`: one hidden layer of 32, noise σ 1; `darc/train_eval.py`: Adam 3e-4);
Δr is clipped to ±10 as `CLDVORL`'s DARA classifier (`DeltaCla.delta_dynamic`) does. A bad
value raises ValueError naming the key, the value and what is allowed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from rllib_asor.algorithms.common.settings import is_int_at_least, is_number, refuse_unknown


@dataclass
class DaraSettings:
    """DARA's settings (the YAML `dara:` block)."""

    eta: float = 0.1
    """η, the weight of Δr added to each source row's reward (r + η·Δr; 0: plain data)."""
    target_dynamics: str = "original"
    """The dataset parts of this dynamics (`.../<task>/<dynamics>/<quality>`) are the target
    domain; every other part is source data whose rewards DARA corrects."""
    hidden: list[int] = dataclasses.field(default_factory=lambda: [32])
    """Hidden ReLU layers of each classifier (DARC: one of 32)."""
    input_noise: float = 1.0
    """σ of the Gaussian noise on the classifiers' inputs in training (DARC: 1.0)."""
    lr: float = 3e-4
    batch_size: int = 256
    """Rows of each domain per classifier step."""
    classifier_steps: int = 5000
    """Classifier steps before the rewards are relabelled (once, on the fixed offline data)."""
    delta_clip: float = 10.0
    """Δr is clipped to ±delta_clip."""
    cache: str | None = "~/.cache/rllib-asor/dara"
    """Directory of relabelled dataset copies, keyed by the data, these settings and the seed
    (None: a temporary directory per run)."""

    @classmethod
    def from_dict(cls, settings: Mapping[str, Any] | None) -> DaraSettings:
        """Validated settings; unknown keys and bad values raise ValueError."""
        settings = dict(settings or {})
        refuse_unknown("dara", "a DARA", settings, [f.name for f in dataclasses.fields(cls)])
        out = cls(**settings)
        out.validate()
        return out

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def validate(self) -> None:
        _check(self, "eta", is_number(0.0, None), "a number >= 0")
        _check(self, "input_noise", is_number(0.0, None), "a number >= 0")
        for key in ("lr", "delta_clip"):
            _check(self, key, is_number(0.0, None, open_low=True), "a number > 0")
        for key in ("batch_size", "classifier_steps"):
            _check(self, key, is_int_at_least(1), "an integer >= 1")
        _check(
            self,
            "target_dynamics",
            lambda v: isinstance(v, str) and v != "",
            "a dynamics name such as original",
        )
        _check(
            self,
            "hidden",
            lambda v: isinstance(v, list | tuple) and all(is_int_at_least(1)(x) for x in v),
            "a list of integers >= 1",
        )
        _check(
            self,
            "cache",
            lambda v: v is None or (isinstance(v, str) and v != ""),
            "null or a directory path",
        )
        self.hidden = [int(x) for x in self.hidden]


def _check(s: DaraSettings, key: str, ok: Any, allowed: str) -> None:
    value = getattr(s, key)
    if not ok(value):
        raise ValueError(f"dara.{key}={value!r} is invalid: allowed {allowed}")
