"""ESCP's own settings (the `escp:` YAML block, `EscpConfig.escp(...)`), validated.

Defaults are ESCP's (`parameter/Parameter.py`, and the README's run command
`--rnn_fix_length 16 --ep_dim 2 --rbf_radius 3000 --use_rmdm --stop_pg_for_ep --bottle_neck`
with the default `kernel_type rbf_element_wise`).
"""

from __future__ import annotations

from typing import Annotated, ClassVar

from pydantic import Field, model_validator

from rllib_asor.algorithms.escp.rmdm import KERNELS
from rllib_asor.settings_model import (
    Allowed,
    BlockSettings,
    IntAtLeast0,
    IntAtLeast1,
    NonNegative,
    Positive,
    one_of,
)

TaskCount = Annotated[int, Field(ge=2), Allowed("an int ≥ 2")]
Share = Annotated[float, Field(ge=0, le=1), Allowed("a number ≥ 0 and ≤ 1")]
Widths = Annotated[
    tuple[Annotated[int, Field(ge=1)], Annotated[int, Field(ge=1)]],
    Field(strict=False),
    Allowed("[fc, gru] positive ints"),
]
Kernel = one_of(KERNELS)


class EscpSettings(BlockSettings):
    """ESCP's settings; each field names ESCP's own parameter."""

    block: ClassVar[str] = "escp"
    label: ClassVar[str] = "an ESCP"

    context_dim: IntAtLeast1 = 2
    """Size of z (`ep_dim`)."""
    history_len: IntAtLeast1 = 16
    """H, steps of (s_t, a_{t−1}) the encoder reads (`rnn_fix_length`)."""
    encoder_hidden: Widths = (128, 64)
    """(fc, GRU) widths of the encoder (`ep_hidden_size`)."""
    context_noise: NonNegative = 0.01
    """Std of the Gaussian noise on z while sampling/training (`bottle_sigma`, `bottle_neck`)."""
    encoder_lr: Positive = 3e-4
    """Adam lr of the encoder (ESCP trains it with the policy's optimizer, `learning_rate`)."""
    consistency_weight: NonNegative = 50.0
    """RMDM consistency weight (`consistency_loss_weight`)."""
    diversity_weight: NonNegative = 0.025
    """RMDM diversity weight (`diversity_loss_weight`)."""
    kernel: Kernel = "rbf_element_wise"
    """Diversity kernel (`kernel_type`): rbf_element_wise | rbf."""
    rbf_radius: Positive = 3000.0
    """RBF coefficient α in exp(−α·d²) (`rbf_radius`)."""
    rmdm_tau: Share = 0.995
    """Smoothing of the per-task moving averages of z (`rmdm_tau`)."""
    rmdm_scale: NonNegative = 1.0
    """Factor on the RMDM loss (`repre_loss_factor`)."""
    rmdm_min_replay: IntAtLeast0 = 100_000
    """Replay steps before RMDM trains the encoder (`minimal_repre_rp_size`)."""
    rmdm_min_task_fraction: Share = 0.5
    """RMDM trains only on batches holding ≥ this fraction of the training tasks."""
    num_tasks: Annotated[TaskCount | None, Allowed("null or an int ≥ 2")] = None
    """Training tasks (`task_num`, 40 in ESCP); None: the tasks seen so far."""
    max_tasks: TaskCount = 256
    """Slots of the per-task moving-average table (distinct dynamics_id values)."""
    target_entropy_ratio: NonNegative = 1.5
    """SAC's target entropy −ratio·|A| when `target_entropy="auto"` (`target_entropy_ratio`)."""
    max_alpha: Positive = 1.0
    """SAC's temperature is clipped to ≤ this (`log_sac_alpha.clamp_max_(0)`)."""

    @model_validator(mode="after")
    def _tasks_fit_the_table(self) -> EscpSettings:
        if self.num_tasks is not None and self.num_tasks > self.max_tasks:
            raise ValueError(
                f"escp.num_tasks={self.num_tasks!r} is not allowed; expected ≤ escp.max_tasks "
                f"({self.max_tasks})"
            )
        return self
