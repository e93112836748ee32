"""`CadmSettings`: CaDM's own settings (the YAML `cadm:` block, `CadmConfig.cadm(...)`).

Defaults are the authors' (`younggyoseo/CaDM run_scripts/model_free/run_ppo_cadm.py`:
`--history_length 10`, `--context_out_dim 10`, `--back_coeff 0.5`, `context_hidden_sizes
(256, 128, 64)`, `hidden_sizes (200,)*4`, `--lr 0.0005`). A bad value raises ValueError
naming the key, the value and what is allowed.
"""

from __future__ import annotations

from typing import Annotated, ClassVar

from pydantic import Field

from rllib_asor.settings_model import Allowed, BlockSettings, IntAtLeast1, NonNegative, Positive

Widths = Annotated[
    tuple[Annotated[int, Field(ge=1)], ...],
    Field(min_length=1, strict=False),
    Allowed("a non-empty list of positive ints"),
]


class CadmSettings(BlockSettings):
    """CaDM's settings; each field names the authors' parameter."""

    block: ClassVar[str] = "cadm"
    label: ClassVar[str] = "a CaDM"

    history_len: IntAtLeast1 = 10
    """Steps of (s_t, a_{t−1}) the context network reads (`history_length`)."""
    context_dim: IntAtLeast1 = 10
    """Size of the context c (`context_out_dim`)."""
    context_hidden: Widths = (256, 128, 64)
    """The context network's hidden ReLU layers (`context_hidden_sizes`)."""
    model_hidden: Widths = (200, 200, 200, 200)
    """The forward and backward models' hidden swish layers (`hidden_sizes`)."""
    back_coeff: NonNegative = 0.5
    """Weight of the backward model's loss (`back_coeff`)."""
    model_lr: Positive = 5e-4
    """Adam lr of the context network and the models (`lr`)."""
    model_weight: NonNegative = 1.0
    """Factor on CaDM's loss (0: the context is not trained)."""
    target_entropy_ratio: NonNegative = 1.0
    """SAC's target entropy −ratio·|A| for `target_entropy="auto"` (SAC's own: 1)."""
