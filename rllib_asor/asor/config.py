"""`AsorConfig`: every ASOR hyperparameter in one typed, validated place.

The same names are used in Python (`with_asor(config, lambda_=0.01)`), in the YAML `asor:`
block and in the metrics (`asor/lambda`). A bad value raises a `ValueError` that names the key,
the value and what is allowed.
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

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

LambdaSpec = float | str | list[list[float]]


def effective_rhos(rho_value: float, rho_count: float, mode: str) -> tuple[float, float]:
    """(ρ1, ρ2) as the partition uses them for `mode` (srpo: ρ2 = 1, count: ρ1 = 1)."""
    if mode == "srpo":
        return rho_value, 1.0
    if mode == "count":
        return 1.0, rho_count
    return rho_value, rho_count


def _fail(key: str, value: Any, allowed: str) -> None:
    raise ValueError(f"asor.{key}={value!r} is invalid: allowed {allowed}")


@dataclass
class AsorConfig:
    """Hyperparameters of ASOR (docs/algorithm.md); defaults chosen by measurement (docs/results.md).

    `preset` fills every field left at None: "robust" (the default) or "paper" (the method as
    the paper states it, for reproduction). Fields given explicitly override the preset.
    """

    preset: str = "robust"
    """robust (default: bounded, normalised, archive-based) | paper (λ·log ω on the batch)."""
    lambda_: LambdaSpec | None = None
    """λ, weight of the bonus b(s) in the reward: a float ≥ 0, a piecewise-linear schedule
    `[[timestep, value], ...]` (like RLlib's lr schedules), or "auto" (dual ascent on the
    discriminator's Jensen-Shannon estimate; our extension, not in the paper).
    robust: 0.05 (× the env reward's running scale); paper: 0.01 (absolute)."""
    lambda_relative: bool | None = None
    """Multiply λ by the env reward's running RMS, so one λ means the same on every env."""
    lambda_warmup: bool | None = None
    """Add no bonus until the critic ranks states (explained variance of V > 0 on a batch)."""
    reward_form: str | None = None
    """log: log ω (paper, ≤ 0); centered: log ω minus its batch mean; gail: −log(1 − ω) ≥ 0;
    logit: the discriminator logit clipped to ±`logit_clip` (AIRL/DAC form, two-signed)."""
    bonus_norm: str | None = None
    """Standardise the bonus, then clip it to ±`bonus_clip`: batch (robust: by this batch's
    mean/std, like PPO's advantage normalisation; keeps the bonus's size fixed relative to the
    reward scale however the discriminator drifts), running (by its running mean/std over all
    batches so far; an earlier robust default), or off (paper)."""
    shaping: str | None = None
    """potential (robust): r + λ·(γ·b(s′) − b(s)) (Ng et al. 1999: the optimal policy cannot
    change; b(s′) = 0 after termination); direct (paper): r + λ·b(s)."""
    bonus_clip: float = 3.0
    """Bound of the normalised bonus: |λ·b| ≤ λ·bonus_clip (× reward scale when relative)."""
    logit_clip: float = 5.0
    """Bound of the logit form's raw bonus."""
    real_source: str | None = None
    """Where D_P ("real") comes from: batch (paper: partition of the current batch) or
    archive (the states of the highest-return episodes so far, per dynamics)."""
    archive_size: int = 4096
    """States kept per dynamics bucket by the archive (real_source="archive")."""
    rho_value: float = 0.5
    """ρ1 ∈ (0, 1]: fraction of the batch with the highest V(s) that forms P."""
    rho_count: float = 0.5
    """ρ2 ∈ (0, 1]: fraction of P with the highest visitation proxy that forms D_P ("real")."""
    mode: str = "asor"
    """Partition: asor (value then count), srpo (value only), count (count only), random."""
    proxy: str = "rnd"
    """Visitation-count proxy: rnd (Random Network Distillation), ensemble (disagreement), or
    rnd_per_dynamics (one RND predictor per dynamics id from `info["dynamics_id"]`; the count
    under the least familiar dynamics — our extension, see rllib_asor.asor.rnd)."""
    log_omega_min: float = -5.0
    """Lower clip of log ω (and of the gail bonus's sign-flipped counterpart), < 0."""
    disc_hiddens: list[int] = field(default_factory=lambda: [256, 256, 256])
    """Discriminator MLP hidden sizes (SRPO: 3×256 ReLU)."""
    disc_lr: float | None = None
    """Adam learning rate of the discriminator (robust 3e-4, paper 1e-3)."""
    disc_grad_penalty: float | None = None
    """Weight of the gradient penalty ‖∇ₛ logit‖² on real samples (AMP/ASE: 5-10)."""
    disc_logit_reg: float | None = None
    """Weight of the squared output-layer weights (ASE's logit regularisation)."""
    disc_weight_decay: float | None = None
    """Adam weight decay of the discriminator."""
    disc_input_norm: bool | None = None
    """Normalise the discriminator's inputs by running mean/std (clipped ±5)."""
    label_smoothing: float = 0.0
    """Targets 1−ε / ε for real / generated; > 0 keeps ω from saturating (docs/results.md, lava world)."""
    aux_epochs: float | None = None
    """Passes of the discriminator and proxy over each train batch; a fraction trains them on
    that share of it. None (default): one pass on PPO and CQL (PPO runs `num_epochs` passes for
    the policy; one keeps ω from saturating, docs/results.md, lava world); one minibatch per
    Learner call on SAC's fast path (its calls hold 16 gradient steps of replayed rows;
    docs/results.md, SAC speed)."""
    rnd_hiddens: list[int] = field(default_factory=lambda: [128, 128])
    """RND target/predictor MLP hidden sizes."""
    rnd_embedding_dim: int = 64
    """RND output dimension."""
    rnd_lr: float = 1e-3
    """Adam learning rate of the RND predictor (or the dynamics ensemble)."""
    dynamics_buckets: int = 16
    """Predictors of `rnd_per_dynamics` and buckets of the archive (dynamics ids modulo this)."""
    ensemble_size: int = 5
    """K, the number of dynamics models when proxy == "ensemble"."""
    lambda_target: float = 0.1
    """ε of the constraint d(dπ, d*) < ε, used only by lambda_ == "auto"."""
    lambda_lr: float = 0.01
    """η_λ, the dual-ascent step of lambda_ == "auto"."""
    lambda_max: float = 1.0
    """Upper bound of λ for lambda_ == "auto"."""
    lambda_init: float = 0.0
    """Starting λ for lambda_ == "auto"."""
    lambda_kp: float = 0.0
    """Proportional gain of lambda_ == "auto": λ = clip(λ_I + Kp·(d̂ − ε), 0, λ_max), λ_I the
    dual-ascent (integral) term — the PI-Lagrangian of Stooke et al. 2020; 0 = dual ascent."""
    bonus_share_max: float | None = None
    """Cap on the bonus's size: mean |λ·b(s)| ≤ this × the env reward's running scale in every
    batch (λ is scaled down when it would exceed it; `asor/share_capped` says when). 0 = no
    cap. Preset robust 0.2, paper 0."""
    obs_keys: list[str] | None = None
    """For Dict observations: the keys the discriminator and proxy see (None = all, flattened)."""
    seed: int | None = None
    """Seed for the random partition mode and the aux networks' initialisation."""

    def __post_init__(self) -> None:
        if self.preset not in PRESETS:
            _fail("preset", self.preset, " | ".join(PRESET_NAMES))
        for key, value in PRESETS[self.preset].items():
            if getattr(self, key) is None:
                setattr(self, key, copy.deepcopy(value))
        self.validate()

    # ------------------------------------------------------------------ validation
    def validate(self) -> None:
        """Raise ValueError naming the first bad key, its value and what is allowed."""
        self._validate_lambda()
        for key in ("rho_value", "rho_count"):
            v = getattr(self, key)
            if not _is_number(v) or not 0.0 < v <= 1.0:
                _fail(key, v, "a number in (0, 1]")
        for key, allowed in (
            ("mode", MODES),
            ("proxy", PROXIES),
            ("reward_form", REWARD_FORMS),
            ("real_source", REAL_SOURCES),
            ("shaping", SHAPINGS),
            ("bonus_norm", BONUS_NORMS),
        ):
            if getattr(self, key) not in allowed:
                _fail(key, getattr(self, key), " | ".join(allowed))
        if not _is_number(self.log_omega_min) or not -1e6 < self.log_omega_min < 0:
            _fail("log_omega_min", self.log_omega_min, "a finite number < 0")
        for key in ("disc_lr", "rnd_lr", "lambda_lr", "bonus_clip", "logit_clip"):
            v = getattr(self, key)
            if not _is_number(v) or v <= 0:
                _fail(key, v, "a number > 0")
        for key in ("disc_grad_penalty", "disc_logit_reg", "disc_weight_decay"):
            v = getattr(self, key)
            if not _is_number(v) or v < 0:
                _fail(key, v, "a finite number ≥ 0")
        for key in ("lambda_relative", "lambda_warmup", "disc_input_norm"):
            if not isinstance(getattr(self, key), bool):
                _fail(key, getattr(self, key), "true or false")
        if self.aux_epochs is not None and (
            not _is_number(self.aux_epochs) or not 0 < self.aux_epochs <= 100
        ):
            _fail("aux_epochs", self.aux_epochs, "a number in (0, 100] or null (the default)")
        if not _is_number(self.label_smoothing) or not 0.0 <= self.label_smoothing < 0.5:
            _fail("label_smoothing", self.label_smoothing, "a number in [0, 0.5)")
        for key in ("disc_hiddens", "rnd_hiddens"):
            v = getattr(self, key)
            if (
                not isinstance(v, Sequence)
                or isinstance(v, str)
                or not v
                or not all(isinstance(h, int) and not isinstance(h, bool) and h > 0 for h in v)
            ):
                _fail(key, v, "a non-empty list of positive integers")
            setattr(self, key, list(v))
        for key in (
            "rnd_embedding_dim",
            "ensemble_size",
            "dynamics_buckets",
            "archive_size",
        ):
            v = getattr(self, key)
            if (
                not isinstance(v, int)
                or isinstance(v, bool)
                or v < (2 if key == "ensemble_size" else 1)
            ):
                _fail(key, v, "an integer ≥ 2" if key == "ensemble_size" else "an integer ≥ 1")
        for key in ("lambda_target", "lambda_max", "lambda_init", "lambda_kp", "bonus_share_max"):
            v = getattr(self, key)
            if not _is_number(v) or v < 0:
                _fail(key, v, "a finite number ≥ 0")
        if self.obs_keys is not None and (
            isinstance(self.obs_keys, str)
            or not isinstance(self.obs_keys, Sequence)
            or not self.obs_keys
            or not all(isinstance(k, str) for k in self.obs_keys)
        ):
            _fail("obs_keys", self.obs_keys, "null or a non-empty list of observation keys")
        if self.seed is not None and (
            not isinstance(self.seed, int) or isinstance(self.seed, bool)
        ):
            _fail("seed", self.seed, "null or an integer")

    def _validate_lambda(self) -> None:
        lam = self.lambda_
        if isinstance(lam, str):
            if lam != "auto":
                _fail("lambda_", lam, 'a number ≥ 0, "auto", or [[timestep, value], ...]')
            return
        if _is_number(lam):
            if lam < 0:
                _fail("lambda_", lam, 'a number ≥ 0, "auto", or [[timestep, value], ...]')
            self.lambda_ = float(lam)
            return
        ok = isinstance(lam, Sequence) and len(lam) > 0
        points: list[list[float]] = []
        if ok:
            for p in lam:
                if (
                    not isinstance(p, Sequence)
                    or len(p) != 2
                    or not all(_is_number(x) for x in p)
                    or p[0] < 0
                    or p[1] < 0
                ):
                    ok = False
                    break
                points.append([float(p[0]), float(p[1])])
        if ok and any(b[0] <= a[0] for a, b in zip(points, points[1:], strict=False)):
            ok = False
        if not ok:
            _fail(
                "lambda_",
                lam,
                'a number ≥ 0, "auto", or a schedule [[timestep, value], ...] with increasing '
                "timesteps ≥ 0 and values ≥ 0",
            )
        self.lambda_ = points

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
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(settings) - known)
        if unknown:
            hints = [
                f"{key!r} (did you mean {close[0]!r}?)" if close else repr(key)
                for key in unknown
                for close in [difflib.get_close_matches(key, known, n=1)]
            ]
            raise ValueError(
                f"asor: unknown key(s) {', '.join(hints)}; allowed: " + ", ".join(sorted(known))
            )
        return cls(**settings)

    def to_dict(self) -> dict[str, Any]:
        """Plain-dict form (what is stored in `learner_config_dict['asor']`)."""
        return dataclasses.asdict(self)

    # ------------------------------------------------------------------ helpers
    @property
    def effective_rhos(self) -> tuple[float, float]:
        """(ρ1, ρ2) as the partition uses them for this mode (srpo: ρ2 = 1, count: ρ1 = 1)."""
        return effective_rhos(self.rho_value, self.rho_count, self.mode)

    @property
    def needs_proxy(self) -> bool:
        """Whether the visitation-count proxy (RND/ensemble) is trained and used."""
        return self.mode in ("asor", "count")


def _is_number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)


def field_docs() -> dict[str, str]:
    """Each `AsorConfig` field's attribute docstring (read from this file's source)."""
    import ast
    import inspect

    try:
        tree = ast.parse(inspect.getsource(AsorConfig))
    except (OSError, TypeError):  # no source shipped (e.g. a zipped install)
        return {f.name: "" for f in dataclasses.fields(AsorConfig)}
    body = tree.body[0].body  # type: ignore[attr-defined]
    docs: dict[str, str] = {}
    for node, nxt in zip(body, body[1:], strict=False):
        if (
            isinstance(node, ast.AnnAssign)
            and isinstance(node.target, ast.Name)
            and isinstance(nxt, ast.Expr)
            and isinstance(nxt.value, ast.Constant)
            and isinstance(nxt.value.value, str)
        ):
            docs[node.target.id] = " ".join(nxt.value.value.split())
    return docs


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
