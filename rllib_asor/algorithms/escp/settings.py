"""ESCP's own settings (the `escp:` YAML block, `EscpConfig.escp(...)`), validated.

Defaults are ESCP's (`parameter/Parameter.py`, and the README's run command
`--rnn_fix_length 16 --ep_dim 2 --rbf_radius 3000 --use_rmdm --stop_pg_for_ep --bottle_neck`
with the default `kernel_type rbf_element_wise`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any

from rllib_asor.algorithms.common.settings import is_int_at_least, is_number, refuse_unknown
from rllib_asor.algorithms.escp.rmdm import KERNELS


@dataclass(frozen=True)
class EscpSettings:
    """ESCP's settings; each field names ESCP's own parameter."""

    context_dim: int = 2
    """Size of z (`ep_dim`)."""
    history_len: int = 16
    """H, steps of (s_t, a_{t−1}) the encoder reads (`rnn_fix_length`)."""
    encoder_hidden: tuple[int, int] = (128, 64)
    """(fc, GRU) widths of the encoder (`ep_hidden_size`)."""
    context_noise: float = 0.01
    """Std of the Gaussian noise on z while sampling/training (`bottle_sigma`, `bottle_neck`)."""
    encoder_lr: float = 3e-4
    """Adam lr of the encoder (ESCP trains it with the policy's optimizer, `learning_rate`)."""
    consistency_weight: float = 50.0
    """RMDM consistency weight (`consistency_loss_weight`)."""
    diversity_weight: float = 0.025
    """RMDM diversity weight (`diversity_loss_weight`)."""
    kernel: str = "rbf_element_wise"
    """Diversity kernel (`kernel_type`): rbf_element_wise | rbf."""
    rbf_radius: float = 3000.0
    """RBF coefficient α in exp(−α·d²) (`rbf_radius`)."""
    rmdm_tau: float = 0.995
    """Smoothing of the per-task moving averages of z (`rmdm_tau`)."""
    rmdm_scale: float = 1.0
    """Factor on the RMDM loss (`repre_loss_factor`)."""
    rmdm_min_replay: int = 100_000
    """Replay steps before RMDM trains the encoder (`minimal_repre_rp_size`)."""
    rmdm_min_task_fraction: float = 0.5
    """RMDM trains only on batches holding ≥ this fraction of the training tasks."""
    num_tasks: int | None = None
    """Training tasks (`task_num`, 40 in ESCP); None: the tasks seen so far."""
    max_tasks: int = 256
    """Slots of the per-task moving-average table (distinct dynamics_id values)."""
    target_entropy_ratio: float = 1.5
    """SAC's target entropy −ratio·|A| when `target_entropy="auto"` (`target_entropy_ratio`)."""
    max_alpha: float = 1.0
    """SAC's temperature is clipped to ≤ this (`log_sac_alpha.clamp_max_(0)`)."""

    def __post_init__(self) -> None:
        _int(self, "context_dim", 1)
        _int(self, "history_len", 1)
        hidden = self.encoder_hidden
        if (
            not isinstance(hidden, (tuple, list))
            or len(hidden) != 2
            or not all(isinstance(h, int) and not isinstance(h, bool) and h >= 1 for h in hidden)
        ):
            raise ValueError(
                f"escp.encoder_hidden={hidden!r} is not allowed; expected [fc, gru] positive ints"
            )
        object.__setattr__(self, "encoder_hidden", tuple(hidden))
        _num(self, "context_noise", 0.0, None)
        _num(self, "encoder_lr", 0.0, None, open_low=True)
        _num(self, "consistency_weight", 0.0, None)
        _num(self, "diversity_weight", 0.0, None)
        if self.kernel not in KERNELS:
            raise ValueError(
                f"escp.kernel={self.kernel!r} is not allowed; expected one of {KERNELS}"
            )
        _num(self, "rbf_radius", 0.0, None, open_low=True)
        _num(self, "rmdm_tau", 0.0, 1.0)
        _num(self, "rmdm_scale", 0.0, None)
        _int(self, "rmdm_min_replay", 0)
        _num(self, "rmdm_min_task_fraction", 0.0, 1.0)
        if self.num_tasks is not None:
            _int(self, "num_tasks", 2)
        _int(self, "max_tasks", 2)
        if self.num_tasks is not None and self.num_tasks > self.max_tasks:
            raise ValueError(
                f"escp.num_tasks={self.num_tasks!r} is not allowed; expected ≤ escp.max_tasks "
                f"({self.max_tasks})"
            )
        _num(self, "target_entropy_ratio", 0.0, None)
        _num(self, "max_alpha", 0.0, None, open_low=True)

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None) -> EscpSettings:
        """Settings from a dict (the `escp:` block); unknown keys raise ValueError."""
        if d is None:
            return cls()
        if isinstance(d, EscpSettings):
            return d
        if not isinstance(d, dict):
            raise ValueError(f"escp={d!r} is not allowed; expected a mapping of ESCP settings")
        refuse_unknown("escp", "an ESCP", sorted(d), [f.name for f in fields(cls)])
        return cls(**d)

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["encoder_hidden"] = list(self.encoder_hidden)
        return out


def _int(s: EscpSettings, key: str, low: int) -> None:
    v = getattr(s, key)
    if not is_int_at_least(low)(v):
        raise ValueError(f"escp.{key}={v!r} is not allowed; expected an int ≥ {low}")


def _num(s: EscpSettings, key: str, low: float, high: float | None, open_low: bool = False) -> None:
    v = getattr(s, key)
    if not is_number(low, high, open_low)(v):
        rng = f"{'>' if open_low else '≥'} {low}" + ("" if high is None else f" and ≤ {high}")
        raise ValueError(f"escp.{key}={v!r} is not allowed; expected a number {rng}")
    object.__setattr__(s, key, float(v))
