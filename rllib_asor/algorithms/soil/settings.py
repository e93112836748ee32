"""`SoilSettings`: SOIL's own settings (the YAML `soil:` block, `SoilConfig.soil(...)`).

Defaults are SOIL's (`yzqin/dexmv-learn tpi/core/config.py`, `_C.SOIL`): a 64-64 tanh inverse
dynamics model, Adam 1e-3, 500 minibatches of 32 per iteration from a buffer of 10^6
transitions, demonstration weight λ0 = 0.1 decaying by λ1 = 0.99 per iteration. A bad value
raises ValueError naming the key, the value and what is allowed.
"""

from __future__ import annotations

from typing import Annotated, ClassVar

from pydantic import Field

from rllib_asor.settings_model import Allowed, BlockSettings, IntAtLeast1, NonNegative, Positive


class SoilSettings(BlockSettings):
    """SOIL's settings."""

    block: ClassVar[str] = "soil"
    label: ClassVar[str] = "a SOIL"

    demonstrations: Annotated[
        str | None, Allowed("a path: an .npz of state-only demonstrations or a dataset dir")
    ] = None
    """State-only expert transitions (`rllib_asor.algorithms.common.demonstrations`)."""
    demo_weight: NonNegative = 0.1
    """λ0: the demonstration term's weight at the first iteration (0: plain PPO / MARWIL)."""
    demo_decay: Annotated[float, Field(ge=0, le=1), Allowed("a number in [0, 1]")] = 0.99
    """λ1: the weight is λ0·λ1^k at training iteration k."""
    idm_hiddens: Annotated[
        tuple[Annotated[int, Field(ge=1)], ...],
        Field(min_length=1, strict=False),
        Allowed("a non-empty list of positive ints"),
    ] = (64, 64)
    """The inverse dynamics model's hidden tanh layers."""
    idm_lr: Positive = 1e-3
    """Adam lr of the inverse dynamics model."""
    idm_steps: IntAtLeast1 = 500
    """Its Adam steps per training iteration (offline: in all, once, before training)."""
    idm_batch_size: IntAtLeast1 = 32
    """Transitions per step of the inverse dynamics model."""
    idm_capacity: IntAtLeast1 = 1_000_000
    """The newest transitions of the policy's that its buffer keeps."""
    evaluation_interval: Annotated[int, Field(ge=0), Allowed("an int ≥ 0")] = 10
    """Offline: evaluate the policy under the data's dynamics every this many iterations
    (`evaluation/...`; 0: never). Online runs report the env runners' returns."""
    evaluation_episodes: IntAtLeast1 = 5
    """Offline: episodes per dynamics of that evaluation."""
    seed: int = 0
    """Seed of the model's initial weights and the row sampling."""
