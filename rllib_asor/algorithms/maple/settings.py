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

from collections.abc import Mapping
from typing import Annotated, Any, ClassVar

from pydantic import ConfigDict, Field, model_validator

from rllib_asor.settings_model import Allowed, Settings

Flag = Annotated[bool, Allowed("true or false")]
AtLeast1 = Annotated[int, Field(ge=1), Allowed("an integer >= 1")]
NonNegative = Annotated[float, Field(ge=0), Allowed("a number >= 0")]
Positive = Annotated[float, Field(gt=0), Allowed("a number > 0")]


def _ensemble_property(schema: dict[str, Any]) -> None:
    """The block's `ensemble:` key (expanded by `expand_ensemble` before validation)."""
    schema["properties"]["ensemble"] = {
        "enum": list(ENSEMBLE_PRESETS),
        "description": "A named ensemble: members, elites and width "
        + "; ".join(
            f"{name} {v['ensemble_members']}/{v['ensemble_elites']}/{v['ensemble_hidden']}"
            for name, v in ENSEMBLE_PRESETS.items()
        )
        + " (keys written beside it win).",
    }


class MapleSettings(Settings):
    """MAPLE's settings (the YAML `maple:` block)."""

    model_config = ConfigDict(json_schema_extra=_ensemble_property)
    block: ClassVar[str] = "maple"
    label: ClassVar[str] = "a MAPLE"

    context: Flag = True
    """True: MAPLE (GRU context for policy and critics); False: MOPO (the context switched off)."""
    horizon: AtLeast1 = 10
    """h, steps per model rollout and per training segment (MAPLE 10; MOPO 5)."""
    penalty_coef: NonNegative = 0.25
    """λ_u, weight of the uncertainty penalty r − λ_u·u (MAPLE 0.25; MOPO 0.5-5 by task)."""
    penalty_clip: NonNegative = 40.0
    """Clip of the uncertainty u (SRPO/torch port 40; the TF code 20)."""
    real_ratio: Annotated[float, Field(ge=0, le=1), Allowed("a number in [0, 1]")] = 0.05
    """Share of real segments in each SAC batch (the rest are model segments)."""
    rollout_batch_size: AtLeast1 = 50_000
    """Model rollouts started per training iteration (one iteration = `steps_per_iteration`)."""
    model_pool_size: AtLeast1 = 250_000
    """Model segments kept (a ring buffer)."""
    checkpoint_model_pool: Flag = False
    """Also save the model pool in checkpoints (~2 KB per segment at h 10: ~0.5 GB at the
    default size), so that a restored run trains on the pool it had; False (as RLlib's
    `store_buffer_in_checkpoints`): a restored run starts from an empty pool, refilled by its
    next iterations' rollouts."""
    steps_per_iteration: AtLeast1 = 1000
    """SAC gradient steps per training iteration (the port's `in_train_epoch`)."""
    hidden_refresh_every: AtLeast1 = 4
    """Iterations between refreshes of the real segments' starting hidden states."""
    gru_hidden: AtLeast1 = 128
    """Width of the context GRU."""
    context_dim: AtLeast1 = 16
    """Size of the context vector the GRU's output is projected to."""
    hiddens: Annotated[
        list[Annotated[int, Field(ge=1)]],
        Field(min_length=1, strict=False),
        Allowed("a non-empty list of integers >= 1"),
    ] = [256, 256]
    """Actor and critic MLP sizes after the context."""
    actor_lr: Positive = 3e-4
    """Adam lr of the policy."""
    critic_lr: Positive = 3e-4
    """Adam lr of the critics."""
    alpha_lr: Positive = 3e-4
    """Temperature lr (the port uses the actor's)."""
    tau: Annotated[float, Field(gt=0, le=1), Allowed("a number in (0, 1]")] = 5e-3
    """Polyak rate of the target critics."""
    ensemble_members: AtLeast1 = 20
    """Dynamics models in the ensemble."""
    ensemble_elites: AtLeast1 = 14
    """Members with the lowest holdout error, the ones model rollouts sample from."""
    ensemble_hidden: AtLeast1 = 256
    """Members, elites and width: the torch port's 20 / 14 / 256 (`ensemble: tf_maple`: 7 / 5 /
    200, the TF code's and MOPO's)."""
    ensemble_layers: AtLeast1 = 4
    """Hidden layers of each dynamics model."""
    ensemble_lr: Positive = 1e-3
    """Adam lr of the dynamics ensemble."""
    ensemble_weight_decay: NonNegative = 7.5e-5
    """Weight decay of the dynamics ensemble."""
    ensemble_batch_size: AtLeast1 = 256
    """Minibatch size of the ensemble's training."""
    ensemble_patience: AtLeast1 = 5
    """Epochs without any member improving on the holdout before the ensemble stops."""
    ensemble_max_epochs: Annotated[
        Annotated[int, Field(ge=1)] | None, Allowed("null or an integer >= 1")
    ] = None
    """Cap on ensemble epochs (None: until `ensemble_patience`, as the port)."""
    ensemble_cache: Annotated[
        Annotated[str, Field(min_length=1)] | None, Allowed("null or a directory path")
    ] = "~/.cache/rllib-asor/maple"
    """Directory of trained ensembles, keyed by dataset, settings and seed (None: no cache),
    so that paired runs (MAPLE vs MAPLE+ASOR) share one ensemble."""
    clip_floor: NonNegative = 100.0
    """Model states are clipped to the data range ± 5 %, but at least to ±clip_floor (the port's
    `np.maximum(obs_max, 100)`); 0 clips to the data range ± 5 % only."""
    evaluation_interval: Annotated[int, Field(ge=0), Allowed("an integer >= 0")] = 10
    """Evaluate the policy every this many iterations (0: never; always at iteration 1 off)."""
    evaluation_episodes: AtLeast1 = 5
    """Episodes per dynamics and evaluation (SRPO: 40)."""

    @model_validator(mode="after")
    def _elites_among_members(self) -> MapleSettings:
        if self.ensemble_elites > self.ensemble_members:
            raise ValueError(
                f"maple.ensemble_elites={self.ensemble_elites!r} is invalid: allowed an integer "
                f"<= ensemble_members ({self.ensemble_members})"
            )
        return self

    @classmethod
    def from_dict(cls, settings: Mapping[str, Any] | None) -> MapleSettings:
        """Validated settings (an `ensemble` name expanded); bad keys and values raise
        ValueError."""
        return cls(**expand_ensemble(settings))


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
