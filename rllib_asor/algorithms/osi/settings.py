"""`OsiSettings`: OSI's own settings (the YAML `osi:` block, `OsiConfig.osi(...)`), validated.

Defaults are the authors' (`VincentYu68/policy_transfer policy_transfer/uposi/train_osi.py`:
`--OSI_hist 10`, OSI layers 256-128-64) where they have one; the rest are ESCP's (the SAC the
universal policy trains with here). A bad value raises ValueError naming the key, the value and
what is allowed.
"""

from __future__ import annotations

from typing import Annotated, ClassVar

from pydantic import Field

from rllib_asor.settings_model import Allowed, BlockSettings, IntAtLeast1, NonNegative, Positive


class OsiSettings(BlockSettings):
    """OSI's settings; each field names the authors' parameter where there is one."""

    block: ClassVar[str] = "osi"
    label: ClassVar[str] = "an OSI"

    history_len: IntAtLeast1 = 10
    """H, steps of (s_t, a_{t−1}) OSI reads (`OSI_hist`)."""
    osi_hidden: Annotated[
        tuple[Annotated[int, Field(ge=1)], ...],
        Field(min_length=1, strict=False),
        Allowed("a non-empty list of positive ints"),
    ] = (256, 128, 64)
    """OSI's hidden ReLU layers (`layers=[256, 128, 64]`)."""
    osi_lr: Positive = 1e-3
    """Adam lr of the OSI network."""
    osi_weight: NonNegative = 1.0
    """Factor on OSI's squared error (0: OSI does not train)."""
    param_dim: Annotated[Annotated[int, Field(ge=1)] | None, Allowed("null or an int ≥ 1")] = None
    """Length of `info["dynamics_params"]`; None: read from the env when the config is built."""
    target_entropy_ratio: NonNegative = 1.0
    """SAC's target entropy −ratio·|A| for `target_entropy="auto"` (SAC's own: 1)."""
