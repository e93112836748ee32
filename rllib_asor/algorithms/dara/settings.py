"""`DaraSettings`: DARA's settings (the YAML `dara:` block), typed and validated.

Classifier sizes, input noise and the loss are DARC's (`google-research/google-research
darc/classifiers.py`: one hidden layer of 32, noise σ 1; `darc/train_eval.py`: Adam 3e-4);
Δr is clipped to ±10 as `CLDVORL`'s DARA classifier (`DeltaCla.delta_dynamic`) does. A bad
value raises ValueError naming the key, the value and what is allowed.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, Any, ClassVar

from pydantic import Field

from rllib_asor.algorithms.maple.settings import AtLeast1, NonNegative, Positive
from rllib_asor.settings_model import Allowed, Settings


class DaraSettings(Settings):
    """DARA's settings (the YAML `dara:` block)."""

    block: ClassVar[str] = "dara"
    label: ClassVar[str] = "a DARA"

    eta: NonNegative = 0.1
    """η, the weight of Δr added to each source row's reward (r + η·Δr; 0: plain data)."""
    target_dynamics: Annotated[
        str, Field(min_length=1), Allowed("a dynamics name such as original")
    ] = "original"
    """The dataset parts of this dynamics (`.../<task>/<dynamics>/<quality>`) are the target
    domain; every other part is source data whose rewards DARA corrects."""
    hidden: Annotated[
        list[Annotated[int, Field(ge=1)]],
        Field(strict=False),
        Allowed("a list of integers >= 1"),
    ] = [32]
    """Hidden ReLU layers of each classifier (DARC: one of 32)."""
    input_noise: NonNegative = 1.0
    """σ of the Gaussian noise on the classifiers' raw inputs in training (DARC: 1.0). Absolute:
    keep it small next to the features that tell the dynamics apart (docs/baselines.md)."""
    lr: Positive = 3e-4
    """Adam lr of the classifiers (DARC: 3e-4)."""
    batch_size: AtLeast1 = 256
    """Rows of each domain per classifier step."""
    classifier_steps: AtLeast1 = 5000
    """Classifier steps before the rewards are relabelled (once, on the fixed offline data)."""
    delta_clip: Positive = 10.0
    """Δr is clipped to ±delta_clip."""
    cache: Annotated[
        Annotated[str, Field(min_length=1)] | None, Allowed("null or a directory path")
    ] = "~/.cache/rllib-asor/dara"
    """Directory of relabelled dataset copies, keyed by the data, these settings and the seed
    (None: a temporary directory per run)."""

    @classmethod
    def from_dict(cls, settings: Mapping[str, Any] | None) -> DaraSettings:
        """Validated settings; unknown keys and bad values raise ValueError."""
        return cls(**dict(settings or {}))
