"""`AsorConfig`: every ASOR hyperparameter in one typed, validated place.

The same names are used in Python (`with_asor(config, lambda_=0.01)`), in the YAML `asor:`
block and in the metrics (`asor/lambda`). A bad value raises a `ValueError` that names the key,
the value and what is allowed.
"""

from __future__ import annotations

import copy
import difflib
from collections.abc import Mapping, Sequence
from typing import Annotated, Any, ClassVar, Literal

from pydantic import Field, field_validator, model_validator

from rllib_asor import settings_model
from rllib_asor.settings_model import Allowed, Settings, one_of

MODES = ("asor", "srpo", "count", "random")
PROXIES = ("rnd", "ensemble", "rnd_per_dynamics")
REWARD_FORMS = ("log", "centered", "gail", "logit")
REAL_SOURCES = ("batch", "archive")
SHAPINGS = ("direct", "potential")
BONUS_NORMS = ("running", "batch", "off")
PRESET_NAMES = ("robust", "paper")
ALGORITHMS = ("CQL", "ESCP", "MAPLE", "PPO", "SAC")
"""RLlib algorithms ASOR works with (`rllib_asor.rllib.wiring` has one Learner class each)."""

PRESETS: dict[str, dict[str, Any]] = {
    # The default: a bounded, two-signed, normalised bonus scaled to the env reward, a
    # discriminator that does not saturate, D_P drawn from an archive of the best episodes
    # per dynamics, and no bonus until the critic ranks states (docs/algorithm.md).
    "robust": {
        "lambda_": 0.05,
        "lambda_relative": True,
        "lambda_warmup": True,
        "shaping": "potential",
        "reward_form": "logit",
        "bonus_norm": "batch",
        "real_source": "archive",
        "disc_lr": 3e-4,
        "disc_grad_penalty": 5.0,
        "disc_logit_reg": 0.01,
        "disc_weight_decay": 1e-4,
        "disc_input_norm": True,
        "bonus_share_max": 0.2,
    },
    # The paper as stated: λ·log ω on the current batch's partition, a fixed absolute λ.
    "paper": {
        "lambda_": 0.01,
        "lambda_relative": False,
        "lambda_warmup": False,
        "shaping": "direct",
        "reward_form": "log",
        "bonus_norm": "off",
        "real_source": "batch",
        "disc_lr": 1e-3,
        "disc_grad_penalty": 0.0,
        "disc_logit_reg": 0.0,
        "disc_weight_decay": 0.0,
        "disc_input_norm": False,
        "bonus_share_max": 0.0,
    },
}
"""Values of the preset-dependent fields; a field given explicitly always wins."""


def effective_rhos(rho_value: float, rho_count: float, mode: str) -> tuple[float, float]:
    """(ρ1, ρ2) as the partition uses them for `mode` (srpo: ρ2 = 1, count: ρ1 = 1)."""
    if mode == "srpo":
        return rho_value, 1.0
    if mode == "count":
        return 1.0, rho_count
    return rho_value, rho_count


Fraction = Annotated[float, Field(gt=0, le=1), Allowed("a number in (0, 1]")]
PositiveNumber = Annotated[float, Field(gt=0), Allowed("a number > 0")]
NonNegative = Annotated[float, Field(ge=0), Allowed("a finite number ≥ 0")]
Flag = Annotated[bool, Allowed("true or false")]
Hiddens = Annotated[
    list[Annotated[int, Field(gt=0)]],
    Field(min_length=1, strict=False),
    Allowed("a non-empty list of positive integers"),
]
Count = Annotated[int, Field(ge=1), Allowed("an integer ≥ 1")]
SchedulePoint = Annotated[
    list[Annotated[float, Field(ge=0)]], Field(min_length=2, max_length=2, strict=False)
]
LambdaSpec = Annotated[
    Annotated[float, Field(ge=0)]
    | Literal["auto"]
    | Annotated[list[SchedulePoint], Field(min_length=1, strict=False)],
    Allowed(
        'a number ≥ 0, "auto", or a schedule [[timestep, value], ...] with increasing '
        "timesteps ≥ 0 and values ≥ 0"
    ),
]


Preset = one_of(PRESET_NAMES)
RewardForm = one_of(REWARD_FORMS)
BonusNorm = one_of(BONUS_NORMS)
Shaping = one_of(SHAPINGS)
RealSource = one_of(REAL_SOURCES)
Mode = one_of(MODES)
Proxy = one_of(PROXIES)


class AsorConfig(Settings):
    """Hyperparameters of ASOR (docs/algorithm.md); defaults chosen by measurement (docs/results.md).

    `preset` fills every field left at None: "robust" (the default) or "paper" (the method as
    the paper states it, for reproduction). Fields given explicitly override the preset.
    """

    block: ClassVar[str] = "asor"

    preset: Preset = "robust"
    """robust (default: bounded, normalised, archive-based) | paper (λ·log ω on the batch)."""
    lambda_: LambdaSpec | None = None
    """λ, weight of the bonus b(s) in the reward: a float ≥ 0, a piecewise-linear schedule
    `[[timestep, value], ...]` (like RLlib's lr schedules), or "auto" (dual ascent on the
    discriminator's Jensen-Shannon estimate; our extension, not in the paper).
    robust: 0.05 (× the env reward's running scale); paper: 0.01 (absolute)."""
    lambda_relative: Flag | None = None
    """Multiply λ by the env reward's running RMS, so one λ means the same on every env."""
    lambda_warmup: Flag | None = None
    """Add no bonus until the critic ranks states (explained variance of V > 0 on a batch)."""
    reward_form: RewardForm | None = None
    """log: log ω (paper, ≤ 0); centered: log ω minus its batch mean; gail: −log(1 − ω) ≥ 0;
    logit: the discriminator logit clipped to ±`logit_clip` (AIRL/DAC form, two-signed)."""
    bonus_norm: BonusNorm | None = None
    """Standardise the bonus, then clip it to ±`bonus_clip`: batch (robust: by this batch's
    mean/std, like PPO's advantage normalisation; keeps the bonus's size fixed relative to the
    reward scale however the discriminator drifts), running (by its running mean/std over all
    batches so far; an earlier robust default), or off (paper)."""
    shaping: Shaping | None = None
    """potential (robust): r + λ·(γ·b(s′) − b(s)) (Ng et al. 1999: the optimal policy cannot
    change; b(s′) = 0 after termination); direct (paper): r + λ·b(s)."""
    bonus_clip: PositiveNumber = 3.0
    """Bound of the normalised bonus: |λ·b| ≤ λ·bonus_clip (× reward scale when relative)."""
    logit_clip: PositiveNumber = 5.0
    """Bound of the logit form's raw bonus."""
    real_source: RealSource | None = None
    """Where D_P ("real") comes from: batch (paper: partition of the current batch) or
    archive (the states of the highest-return episodes so far, per dynamics)."""
    archive_size: Count = 4096
    """States kept per dynamics bucket by the archive (real_source="archive")."""
    rho_value: Fraction = 0.5
    """ρ1 ∈ (0, 1]: fraction of the batch with the highest V(s) that forms P."""
    rho_count: Fraction = 0.5
    """ρ2 ∈ (0, 1]: fraction of P with the highest visitation proxy that forms D_P ("real")."""
    mode: Mode = "asor"
    """Partition: asor (value then count), srpo (value only), count (count only), random."""
    proxy: Proxy = "rnd"
    """Visitation-count proxy: rnd (Random Network Distillation), ensemble (disagreement), or
    rnd_per_dynamics (one RND predictor per dynamics id from `info["dynamics_id"]`; the count
    under the least familiar dynamics — our extension, see rllib_asor.asor.proxy)."""
    log_omega_min: Annotated[float, Field(gt=-1e6, lt=0), Allowed("a finite number < 0")] = -5.0
    """Lower clip of log ω (and of the gail bonus's sign-flipped counterpart), < 0."""
    disc_hiddens: Hiddens = [256, 256, 256]
    """Discriminator MLP hidden sizes (SRPO: 3×256 ReLU)."""
    disc_lr: PositiveNumber | None = None
    """Adam learning rate of the discriminator (robust 3e-4, paper 1e-3)."""
    disc_grad_penalty: NonNegative | None = None
    """Weight of the gradient penalty ‖∇ₛ logit‖² on real samples (AMP/ASE: 5-10)."""
    disc_logit_reg: NonNegative | None = None
    """Weight of the squared output-layer weights (ASE's logit regularisation)."""
    disc_weight_decay: NonNegative | None = None
    """Adam weight decay of the discriminator."""
    disc_input_norm: Flag | None = None
    """Normalise the discriminator's inputs by running mean/std (clipped ±5)."""
    label_smoothing: Annotated[float, Field(ge=0, lt=0.5), Allowed("a number in [0, 0.5)")] = 0.0
    """Targets 1−ε / ε for real / generated; > 0 keeps ω from saturating (docs/results.md, lava world)."""
    aux_epochs: Annotated[
        Annotated[float, Field(gt=0, le=100)] | None,
        Allowed("a number in (0, 100] or null (the default)"),
    ] = None
    """Passes of the discriminator and proxy over each train batch; a fraction trains them on
    that share of it. None (default): one pass on PPO and CQL (PPO runs `num_epochs` passes for
    the policy; one keeps ω from saturating, docs/results.md, lava world); one minibatch per
    Learner call on SAC's fast path (its calls hold 16 gradient steps of replayed rows;
    docs/results.md, SAC speed)."""
    rnd_hiddens: Hiddens = [128, 128]
    """RND target/predictor MLP hidden sizes."""
    rnd_embedding_dim: Count = 64
    """RND output dimension."""
    rnd_lr: PositiveNumber = 1e-3
    """Adam learning rate of the RND predictor (or the dynamics ensemble)."""
    dynamics_buckets: Count = 16
    """Predictors of `rnd_per_dynamics` and buckets of the archive (dynamics ids modulo this)."""
    ensemble_size: Annotated[int, Field(ge=2), Allowed("an integer ≥ 2")] = 5
    """K, the number of dynamics models when proxy == "ensemble"."""
    lambda_target: NonNegative = 0.1
    """ε of the constraint d(dπ, d*) < ε, used only by lambda_ == "auto"."""
    lambda_lr: PositiveNumber = 0.01
    """η_λ, the dual-ascent step of lambda_ == "auto"."""
    lambda_max: NonNegative = 1.0
    """Upper bound of λ for lambda_ == "auto"."""
    lambda_init: NonNegative = 0.0
    """Starting λ for lambda_ == "auto"."""
    lambda_kp: NonNegative = 0.0
    """Proportional gain of lambda_ == "auto": λ = clip(λ_I + Kp·(d̂ − ε), 0, λ_max), λ_I the
    dual-ascent (integral) term — the PI-Lagrangian of Stooke et al. 2020; 0 = dual ascent."""
    bonus_share_max: NonNegative | None = None
    """Cap on the bonus's size: mean |λ·b(s)| ≤ this × the env reward's running scale in every
    batch (λ is scaled down when it would exceed it; `asor/share_capped` says when). 0 = no
    cap. Preset robust 0.2, paper 0."""
    obs_keys: Annotated[
        Annotated[list[str], Field(min_length=1, strict=False)] | None,
        Allowed("null or a non-empty list of observation keys"),
    ] = None
    """For Dict observations: the keys the discriminator and proxy see (None = all, flattened)."""
    seed: Annotated[int | None, Allowed("null or an integer")] = None
    """Seed for the random partition mode and the aux networks' initialisation."""

    @model_validator(mode="before")
    @classmethod
    def _fill_from_preset(cls, data: Any) -> Any:
        """Fields left at None take the preset's value (validated like a given one)."""
        if not isinstance(data, dict):
            return data
        preset = PRESETS.get(data.get("preset", "robust"))
        if preset is None:
            return data  # the preset field refuses it
        return {**data, **{k: copy.deepcopy(v) for k, v in preset.items() if data.get(k) is None}}

    @field_validator("lambda_")
    @classmethod
    def _schedule_increases(cls, lam: Any) -> Any:
        if isinstance(lam, list) and any(b[0] <= a[0] for a, b in zip(lam, lam[1:], strict=False)):
            raise ValueError("timesteps must increase")
        return lam

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_dict(cls, settings: Mapping[str, Any] | None) -> AsorConfig:
        """Build from a plain dict (YAML `asor:` block); unknown keys raise ValueError.

        `lambda` is accepted as an alias of `lambda_` (YAML users write it naturally).
        """
        settings = dict(settings or {})
        if "lambda" in settings:
            if "lambda_" in settings:
                raise ValueError("asor: give either 'lambda' or 'lambda_', not both")
            settings["lambda_"] = settings.pop("lambda")
        return cls(**settings)

    @classmethod
    def unknown_keys(cls, unknown: Sequence[str]) -> str:
        """`asor: unknown key(s) 'rho_valu' (did you mean 'rho_value'?); allowed: ...`."""
        known = sorted(cls.model_fields)
        hints = [
            f"{key!r} (did you mean {close[0]!r}?)" if close else repr(key)
            for key in sorted(unknown)
            for close in [difflib.get_close_matches(key, known, n=1)]
        ]
        return f"asor: unknown key(s) {', '.join(hints)}; allowed: " + ", ".join(known)

    # ------------------------------------------------------------------ helpers
    @property
    def effective_rhos(self) -> tuple[float, float]:
        """(ρ1, ρ2) as the partition uses them for this mode (srpo: ρ2 = 1, count: ρ1 = 1)."""
        return effective_rhos(self.rho_value, self.rho_count, self.mode)

    @property
    def needs_proxy(self) -> bool:
        """Whether the visitation-count proxy (RND/ensemble) is trained and used."""
        return self.mode in ("asor", "count")


def field_docs() -> dict[str, str]:
    """Each `AsorConfig` field's description (its attribute docstring), on one line."""
    return settings_model.field_docs(AsorConfig)


def settings_help() -> str:
    """Every setting with its robust / paper default and its doc, for docstrings and help()."""
    robust, paper = AsorConfig(), AsorConfig(preset="paper")
    lines = ["Settings (robust default | paper preset where they differ):"]
    for name, doc in field_docs().items():
        a, b = getattr(robust, name), getattr(paper, name)
        default = f"{a!r}" if a == b else f"{a!r} | paper {b!r}"
        lines.append(f"    {name} = {default}\n        {doc}")
    return "\n".join(lines)


AsorConfig.__doc__ = f"{AsorConfig.__doc__.rstrip()}\n\n    " + settings_help().replace(
    "\n", "\n    "
)
