"""`MapleSettings`: MAPLE's (and MOPO's) own hyperparameters, typed and validated.

Defaults follow the PyTorch code MAPLE+SRPO runs on (`AIDefender/SRPO
offlinerl/config/algo/maple_config_st.py`, `maple_config.py`: an ensemble of 20 members, 14
elites, 4×256 swish) except docs/maple.md's deviations. `ensemble: tf_maple` (a key of the block,
expanded on the way in) picks the TensorFlow MAPLE's / MOPO's smaller ensemble instead (7
members, 5 elites, 4×200: `xionghuichen/MAPLE examples/config/d4rl/base_maple.py`,
`polixir/OfflineRL offlinerl/config/algo/mopo_config.py`), which the default was before.
The same names are the YAML `maple:` block. A bad value raises ValueError naming the key, the
value and what is allowed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from rllib_asor.algorithms.common.settings import is_int_at_least, is_number, refuse_unknown


@dataclass
class MapleSettings:
    """MAPLE's settings (the YAML `maple:` block)."""

    context: bool = True
    """True: MAPLE (GRU context for policy and critics); False: MOPO (the context switched off)."""
    horizon: int = 10
    """h, steps per model rollout and per training segment (MAPLE 10; MOPO 5)."""
    penalty_coef: float = 0.25
    """λ_u, weight of the uncertainty penalty r − λ_u·u (MAPLE 0.25; MOPO 0.5-5 by task)."""
    penalty_clip: float = 40.0
    """Clip of the uncertainty u (SRPO/torch port 40; the TF code 20)."""
    real_ratio: float = 0.05
    """Share of real segments in each SAC batch (the rest are model segments)."""
    rollout_batch_size: int = 50_000
    """Model rollouts started per training iteration (one iteration = `steps_per_iteration`)."""
    model_pool_size: int = 250_000
    """Model segments kept (a ring buffer)."""
    checkpoint_model_pool: bool = False
    """Also save the model pool in checkpoints (~2 KB per segment at h 10: ~0.5 GB at the
    default size), so that a restored run trains on the pool it had; False (as RLlib's
    `store_buffer_in_checkpoints`): a restored run starts from an empty pool, refilled by its
    next iterations' rollouts."""
    steps_per_iteration: int = 1000
    """SAC gradient steps per training iteration (the port's `in_train_epoch`)."""
    hidden_refresh_every: int = 4
    """Iterations between refreshes of the real segments' starting hidden states."""
    gru_hidden: int = 128
    context_dim: int = 16
    hiddens: list[int] = dataclasses.field(default_factory=lambda: [256, 256])
    """Actor and critic MLP sizes after the context."""
    actor_lr: float = 3e-4
    critic_lr: float = 3e-4
    alpha_lr: float = 3e-4
    """Temperature lr (the port uses the actor's)."""
    tau: float = 5e-3
    ensemble_members: int = 20
    ensemble_elites: int = 14
    ensemble_hidden: int = 256
    """Members, elites and width: the torch port's 20 / 14 / 256 (`ensemble: tf_maple`: 7 / 5 /
    200, the TF code's and MOPO's)."""
    ensemble_layers: int = 4
    ensemble_lr: float = 1e-3
    ensemble_weight_decay: float = 7.5e-5
    ensemble_batch_size: int = 256
    ensemble_patience: int = 5
    """Epochs without any member improving on the holdout before the ensemble stops."""
    ensemble_max_epochs: int | None = None
    """Cap on ensemble epochs (None: until `ensemble_patience`, as the port)."""
    ensemble_cache: str | None = "~/.cache/rllib-asor/maple"
    """Directory of trained ensembles, keyed by dataset, settings and seed (None: no cache),
    so that paired runs (MAPLE vs MAPLE+ASOR) share one ensemble."""
    clip_floor: float = 100.0
    """Model states are clipped to the data range ± 5 %, but at least to ±clip_floor (the port's
    `np.maximum(obs_max, 100)`); 0 clips to the data range ± 5 % only."""
    evaluation_interval: int = 10
    """Evaluate the policy every this many iterations (0: never; always at iteration 1 off)."""
    evaluation_episodes: int = 5
    """Episodes per dynamics and evaluation (SRPO: 40)."""

    @classmethod
    def from_dict(cls, settings: Mapping[str, Any] | None) -> MapleSettings:
        """Validated settings; unknown keys and bad values raise ValueError."""
        settings = expand_ensemble(settings)
        names = [f.name for f in dataclasses.fields(cls)]
        refuse_unknown("maple", "a MAPLE", settings, names)
        out = cls(**settings)
        out.validate()
        return out

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def validate(self) -> None:
        for key in ("context", "checkpoint_model_pool"):
            _check(self, key, lambda v: isinstance(v, bool), "true or false")
        for key in (
            "horizon",
            "rollout_batch_size",
            "model_pool_size",
            "steps_per_iteration",
            "hidden_refresh_every",
            "gru_hidden",
            "context_dim",
            "ensemble_members",
            "ensemble_elites",
            "ensemble_hidden",
            "ensemble_layers",
            "ensemble_batch_size",
            "ensemble_patience",
            "evaluation_episodes",
        ):
            _check(self, key, is_int_at_least(1), "an integer >= 1")
        _check(self, "evaluation_interval", is_int_at_least(0), "an integer >= 0")
        _check(
            self,
            "ensemble_max_epochs",
            lambda v: v is None or is_int_at_least(1)(v),
            "null or an integer >= 1",
        )
        for key in ("penalty_coef", "penalty_clip", "clip_floor", "ensemble_weight_decay"):
            _check(self, key, is_number(0.0, None), "a number >= 0")
        for key in ("actor_lr", "critic_lr", "alpha_lr", "ensemble_lr"):
            _check(self, key, is_number(0.0, None, open_low=True), "a number > 0")
        _check(self, "tau", is_number(0.0, 1.0, open_low=True), "a number in (0, 1]")
        _check(self, "real_ratio", is_number(0.0, 1.0), "a number in [0, 1]")
        _check(
            self,
            "hiddens",
            lambda v: (
                isinstance(v, list | tuple) and len(v) > 0 and all(is_int_at_least(1)(x) for x in v)
            ),
            "a non-empty list of integers >= 1",
        )
        _check(
            self,
            "ensemble_cache",
            lambda v: v is None or (isinstance(v, str) and v != ""),
            "null or a directory path",
        )
        if self.ensemble_elites > self.ensemble_members:
            raise ValueError(
                f"maple.ensemble_elites={self.ensemble_elites!r} is invalid: allowed an integer "
                f"<= ensemble_members ({self.ensemble_members})"
            )
        self.hiddens = [int(x) for x in self.hiddens]


def _check(s: MapleSettings, key: str, ok: Any, allowed: str) -> None:
    value = getattr(s, key)
    if not ok(value):
        raise ValueError(f"maple.{key}={value!r} is invalid: allowed {allowed}")


MOPO_DEFAULTS: dict[str, Any] = {"context": False, "horizon": 5, "penalty_coef": 1.0}
"""MOPO = MAPLE with the context off; h 5 and λ 1 where `MOPO_DATASETS` has no entry for the
data (`MopoConfig` takes h and λ from there when the user sets neither)."""

ENSEMBLE_PRESETS: dict[str, dict[str, int]] = {
    "torch_port": {"ensemble_members": 20, "ensemble_elites": 14, "ensemble_hidden": 256},
    "tf_maple": {"ensemble_members": 7, "ensemble_elites": 5, "ensemble_hidden": 200},
}
"""`maple.ensemble`: the torch port's ensemble (the default, the paper's runs) or the TF MAPLE's
and MOPO's (the default before; the finished MAPLE Hopper study used it)."""


def expand_ensemble(settings: Mapping[str, Any] | None) -> dict[str, Any]:
    """`settings` with an `ensemble` preset name replaced by its three values (keys written
    beside it win); ValueError for an unknown name."""
    out = dict(settings or {})
    if "ensemble" not in out:
        return out
    name = out.pop("ensemble")
    if not isinstance(name, str) or name not in ENSEMBLE_PRESETS:
        raise ValueError(
            f"maple.ensemble={name!r} is invalid: allowed {' | '.join(ENSEMBLE_PRESETS)}"
        )
    return {**ENSEMBLE_PRESETS[name], **out}


MOPO_DATASETS: dict[tuple[str, str], tuple[int, float]] = {
    ("halfcheetah", "random"): (5, 0.5),
    ("halfcheetah", "medium"): (1, 1.0),
    ("halfcheetah", "medium-replay"): (5, 1.0),
    ("halfcheetah", "medium-expert"): (5, 5.0),
    ("hopper", "random"): (5, 1.0),
    ("hopper", "medium"): (5, 5.0),
    ("hopper", "medium-replay"): (5, 1.0),
    ("hopper", "medium-expert"): (5, 1.0),
    ("walker2d", "random"): (1, 1.0),
    ("walker2d", "medium"): (5, 5.0),
    ("walker2d", "medium-replay"): (1, 1.0),
    ("walker2d", "medium-expert"): (1, 2.0),
}
"""(task, dataset) → (h, λ) as MOPO sets them (`tianheyu927/mopo examples/config/d4rl/
<task>_<dataset>.py`: `rollout_length`, `penalty_coeff`; its `mixed` is D4RL's medium-replay)."""


def mopo_dataset_settings(paths: list[str]) -> dict[str, Any]:
    """`{"horizon", "penalty_coef"}` MOPO uses for the dataset of these part dirs
    (`.../<task>/<dynamics>/<quality>`; medium and expert parts together are medium-expert);
    {} when MOPO has no setting for it."""
    parts = [p.rstrip("/").split("/") for p in paths]
    tasks = {p[-3] for p in parts if len(p) >= 3}
    qualities = {p[-1] for p in parts}
    if len(tasks) != 1:
        return {}
    quality = "medium-expert" if qualities == {"medium", "expert"} else "/".join(sorted(qualities))
    found = MOPO_DATASETS.get((tasks.pop(), quality))
    return {} if found is None else {"horizon": found[0], "penalty_coef": found[1]}
